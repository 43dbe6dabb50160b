// Device-side helpers of the kernels.  The per-pixel maths (reprojection, bilinear sampling, weighting, Jacobian
// rows, similarity term; mirroring droidw_cli.geometry.projection / sampling and droidw_cli.ba.uncertainty) is
// droidw_cli/ba/csrc/droidw_pixel.h, shared with the native CPU backend, whose tests run it on every CPU.
#pragma once

#include <cuda_runtime.h>

#include "droidw_ba.h"

namespace droidw {

constexpr int kThreads = 256;          // threads per block
constexpr int kWarp = 32;
constexpr unsigned kFullMask = 0xffffffffu;
constexpr int64_t kMaxGridY = 65535;   // one block row per edge

// Tree sum over a warp (lane 0 holds the total); the order is fixed, so the result is reproducible.
template <typename T>
__device__ __forceinline__ T warp_sum(T v) {
  for (int off = kWarp / 2; off > 0; off >>= 1) v += __shfl_down_sync(kFullMask, v, off);
  return v;
}

}  // namespace droidw

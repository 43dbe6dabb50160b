// Device-side reprojection, bilinear sampling and weighting, mirroring
// droidw_cli.geometry.projection / sampling and droidw_cli.ba.uncertainty.
#pragma once

#include <cuda_runtime.h>

#include "droidw_ba.h"

namespace droidw {

constexpr int kThreads = 256;          // threads per block
constexpr int kWarp = 32;
constexpr unsigned kFullMask = 0xffffffffu;
constexpr int kRelStride = 12;         // R (9) + t (3) per edge
constexpr int64_t kMaxGridY = 65535;   // one block row per edge

struct Pinhole {
  float fx, fy, cx, cy;
};

// The reprojection of one pixel of frame i into frame j (Eq. 1).
struct Projected {
  float x, y, z;  // x^ = X/Z, y^ = Y/Z, z = 1/Z (1 where invalid)
  float px, py;   // p_ij
  float xbar, ybar;
  bool valid;
};

__device__ __forceinline__ Projected project_pixel(const float* __restrict__ g, const Pinhole& k, int u, int v,
                                                   float d, float min_depth) {
  Projected o;
  o.xbar = (static_cast<float>(u) - k.cx) / k.fx;
  o.ybar = (static_cast<float>(v) - k.cy) / k.fy;
  const float X = g[0] * o.xbar + g[1] * o.ybar + g[2] + g[9] * d;
  const float Y = g[3] * o.xbar + g[4] * o.ybar + g[5] + g[10] * d;
  const float Z = g[6] * o.xbar + g[7] * o.ybar + g[8] + g[11] * d;
  o.valid = (d > 0.0f) && (d * min_depth <= 1.0f) && (Z >= min_depth * d);
  o.z = 1.0f / (o.valid ? Z : 1.0f);
  o.x = X * o.z;
  o.y = Y * o.z;
  o.px = k.fx * o.x + k.cx;
  o.py = k.fy * o.y + k.cy;
  return o;
}

// Border-clamped bilinear corners: (x0,y0), (x0+1,y0), (x0,y0+1), (x0+1,y0+1) as flat indices.
struct Bilinear {
  int idx[4];
  float w[4];
};

__device__ __forceinline__ Bilinear bilinear_corners(float x, float y, int h, int w) {
  const float xc = fminf(fmaxf(x, 0.0f), static_cast<float>(w - 1));
  const float yc = fminf(fmaxf(y, 0.0f), static_cast<float>(h - 1));
  const float x0 = fminf(floorf(xc), static_cast<float>(w - 2));
  const float y0 = fminf(floorf(yc), static_cast<float>(h - 2));
  const float ax = xc - x0, ay = yc - y0;
  const float bx = 1.0f - ax, by = 1.0f - ay;
  Bilinear b;
  const int base = static_cast<int>(y0) * w + static_cast<int>(x0);
  b.idx[0] = base;
  b.idx[1] = base + 1;
  b.idx[2] = base + w;
  b.idx[3] = base + w + 1;
  b.w[0] = bx * by;
  b.w[1] = ax * by;
  b.w[2] = bx * ay;
  b.w[3] = ax * ay;
  return b;
}

__device__ __forceinline__ bool inside_image(float x, float y, int h, int w) {
  return x >= 0.0f && x <= static_cast<float>(w - 1) && y >= 0.0f && y <= static_cast<float>(h - 1);
}

__device__ __forceinline__ float weight_factor(float u, int mode) {
  if (mode == kUncertaintyClamp) {
    const float f = 1.0f / fmaxf(kClampSlope * u - kClampOffset, kClampFloor);
    return fminf(fmaxf(f, 0.0f), 1.0f);
  }
  if (mode == kUncertaintyInverse) return 1.0f / u;
  return 1.0f;
}

// Tree sum over a warp (lane 0 holds the total); the order is fixed, so the result is reproducible.
template <typename T>
__device__ __forceinline__ T warp_sum(T v) {
  for (int off = kWarp / 2; off > 0; off >>= 1) v += __shfl_down_sync(kFullMask, v, off);
  return v;
}

}  // namespace droidw

// The rigid reprojection of Eq. 1, p_ij = Pi(G_ij Pi^-1(p_i, d_i)), of every pixel of frame ii[k] into frame jj[k],
// with its validity (depth >= min_depth in both frames): one thread per edge, project_pixel of droidw_pixel.h.
#include "native_ba.h"

#include <ATen/ops/empty.h>

namespace droidw {
namespace native {

std::vector<at::Tensor> reproject(at::Tensor rel, at::Tensor disps, at::Tensor intrinsics,
                                     at::Tensor ii, double min_depth) {
  TORCH_CHECK(rel.device().is_cpu() && rel.is_contiguous() && rel.scalar_type() == at::kFloat, "rel: float32 CPU");
  TORCH_CHECK(disps.device().is_cpu() && disps.is_contiguous() && disps.scalar_type() == at::kFloat && disps.dim() == 3,
              "disps: contiguous float32 (N, H, W)");
  TORCH_CHECK(ii.scalar_type() == at::kLong && ii.is_contiguous(), "ii: contiguous int64");
  auto intr = intrinsics.to(at::kFloat).contiguous();
  const float* kp = intr.data_ptr<float>();
  const Pinhole cam{kp[0], kp[1], kp[2], kp[3]};
  const int height = static_cast<int>(disps.size(1)), width = static_cast<int>(disps.size(2));
  const int64_t hw = static_cast<int64_t>(height) * width;
  const int64_t e = ii.size(0);
  at::Tensor coords = at::empty({e, height, width, 2}, disps.options());
  at::Tensor valid = at::empty({e, height, width}, disps.options().dtype(at::kBool));
  const float* g0 = rel.data_ptr<float>();
  const float* d0 = disps.data_ptr<float>();
  const int64_t* frames = ii.data_ptr<int64_t>();
  float* co = coords.data_ptr<float>();
  bool* va = valid.data_ptr<bool>();
  const float md = static_cast<float>(min_depth);
  at::parallel_for(0, e, 1, [&](int64_t lo, int64_t hi) {
    for (int64_t k = lo; k < hi; ++k) {
      const float* g = g0 + k * kRelStride;
      const float* d = d0 + frames[k] * hw;
      for (int64_t p = 0; p < hw; ++p) {
        const Projected o = project_pixel(g, cam, static_cast<int>(p % width), static_cast<int>(p / width), d[p], md);
        co[(k * hw + p) * 2] = o.px;
        co[(k * hw + p) * 2 + 1] = o.py;
        va[k * hw + p] = o.valid;
      }
    }
  });
  return {coords, valid};
}

}  // namespace native
}  // namespace droidw

// The uncertainty data term gamma_data E_sim and its d/du map (DROID-W Eq. 7, droidw_cli.ba.uncertainty).  For
// E_sim edge k (frame i -> j, weight omega_k) and pixel p with bilinear corners q_c, weights w_c of p_ij in frame j:
//   F_ij = sum_c w_c F_j[q_c],  cos = F_i . F_ij / max(|F_i| |F_ij|, eps),  u_ij = sum_c w_c u_j[q_c]
//   t = omega_k gamma_data valid (1 - s) / (u_i u_ij),   G[i, p] -= t / u_i,   G[j, q_c] -= w_c t / u_ij
// Each edge scatters into its own two maps (one thread, pixel order); the maps of a frame are then added in edge
// order, so the result does not depend on the number of threads (no atomics).
#include "native_ba.h"

#include <ATen/ops/full.h>
#include <ATen/ops/zeros.h>

namespace droidw {
namespace native {
namespace {

void check(const at::Tensor& t, const char* name, at::ScalarType type) {
  TORCH_CHECK(t.device().is_cpu(), name, " must be a CPU tensor");
  TORCH_CHECK(t.is_contiguous(), name, " must be contiguous");
  TORCH_CHECK(t.scalar_type() == type, name, " has the wrong dtype");
}

// One edge: its maps gi (terms at frame i's pixels) and gj (at frame j's corners); returns sum_p t.
double similarity_edge(const SimilarityConfig& cfg, const SimilarityInputs& in, int64_t k, int height, int width,
                       int channels, float* gi, float* gj) {
  const int hw = height * width;
  const int64_t fi = in.ii.data_ptr<int64_t>()[k], fj = in.jj.data_ptr<int64_t>()[k];
  const float* g = in.rel.data_ptr<float>() + k * kRelStride;
  const float* disp = in.disps.data_ptr<float>() + fi * hw;
  const float* feats = in.features.data_ptr<float>();
  const float* norms = in.norms.data_ptr<float>() + fi * hw;
  const float* u = in.u.data_ptr<float>();
  const float* target = cfg.geo_sigma > 0.0f ? in.target.data_ptr<float>() + k * hw * 2 : nullptr;
  const float gamma_omega = cfg.gamma_data * in.omega.data_ptr<float>()[k];
  const Pinhole cam{cfg.fx, cfg.fy, cfg.cx, cfg.cy};
  std::vector<float> fij(channels);
  double loss = 0.0;
  for (int p = 0; p < hw; ++p) {
    const Projected o = project_pixel(g, cam, p % width, p / width, disp[p], cfg.min_depth);
    const bool valid = o.valid && inside_image(o.px, o.py, height, width);
    if (!valid) continue;  // t = 0: no loss, no gradient
    const Bilinear b = bilinear_corners(o.px, o.py, height, width);
    const float* fi_row = feats + (fi * hw + p) * channels;
    const float* c0 = feats + (fj * hw + b.idx[0]) * channels;
    const float* c1 = feats + (fj * hw + b.idx[1]) * channels;
    const float* c2 = feats + (fj * hw + b.idx[2]) * channels;
    const float* c3 = feats + (fj * hw + b.idx[3]) * channels;
    float dot = 0.0f, sq = 0.0f;
#pragma omp simd reduction(+ : dot, sq)
    for (int c = 0; c < channels; ++c) {
      const float v = b.w[0] * c0[c] + b.w[1] * c1[c] + b.w[2] * c2[c] + b.w[3] * c3[c];
      dot += fi_row[c] * v;
      sq += v * v;
    }
    const float cosv = dot / fmaxf(sqrtf(sq) * norms[p], kCosEps);
    const float residual = target != nullptr ? hypotf(target[2 * p] - o.px, target[2 * p + 1] - o.py) : -1.0f;
    const float sim = similarity_score(cosv, cfg.sim_threshold, residual, cfg.geo_sigma);
    const float ui = u[fi * hw + p];
    const float uij = bilinear_sample(u + fj * hw, b);
    const float t = similarity_term(sim, valid, gamma_omega, ui, uij);
    loss += t;
    gi[p] -= t / ui;
    const float gij = -t / uij;
    for (int c = 0; c < 4; ++c) gj[b.idx[c]] += b.w[c] * gij;
  }
  return loss;
}

}  // namespace

std::vector<at::Tensor> similarity(const SimilarityConfig& cfg, const SimilarityInputs& in) {
  check(in.rel, "rel", at::kFloat);
  check(in.disps, "disps", at::kFloat);
  check(in.ii, "ii", at::kLong);
  check(in.jj, "jj", at::kLong);
  check(in.omega, "omega", at::kFloat);
  check(in.features, "features", at::kFloat);
  check(in.norms, "norms", at::kFloat);
  check(in.u, "u", at::kFloat);
  TORCH_CHECK(in.features.dim() == 4, "features must be (N, H, W, C) channels-last rows");
  if (cfg.geo_sigma > 0.0f) {
    check(in.target, "target", at::kFloat);
    TORCH_CHECK(in.target.size(0) == in.ii.size(0), "target must have one row per sim edge");
  }
  const int64_t n = in.features.size(0);
  const int height = static_cast<int>(in.features.size(1)), width = static_cast<int>(in.features.size(2));
  const int channels = static_cast<int>(in.features.size(3));
  const int64_t hw = static_cast<int64_t>(height) * width;
  const int64_t e = in.ii.size(0);
  at::Tensor parts = at::zeros({e, 2, hw}, in.u.options());  // per edge: its frame-i map, its frame-j map
  std::vector<double> losses(e, 0.0);
  float* pm = parts.data_ptr<float>();
  at::parallel_for(0, e, 1, [&](int64_t lo, int64_t hi) {
    for (int64_t k = lo; k < hi; ++k)
      losses[k] = similarity_edge(cfg, in, k, height, width, channels, pm + k * 2 * hw, pm + (k * 2 + 1) * hw);
  });
  // every frame's map: its edges' maps in edge order
  const int64_t* ii = in.ii.data_ptr<int64_t>();
  const int64_t* jj = in.jj.data_ptr<int64_t>();
  at::Tensor grad = at::zeros({n, hw}, in.u.options());
  float* gm = grad.data_ptr<float>();
  at::parallel_for(0, n, 1, [&](int64_t lo, int64_t hi) {
    for (int64_t f = lo; f < hi; ++f)
      for (int64_t k = 0; k < e; ++k)
        for (int side = 0; side < 2; ++side) {
          if ((side == 0 ? ii[k] : jj[k]) != f) continue;
          const float* src = pm + (k * 2 + side) * hw;
          float* dst = gm + f * hw;
#pragma omp simd
          for (int64_t p = 0; p < hw; ++p) dst[p] += src[p];
        }
  });
  double loss = 0.0;
  for (int64_t k = 0; k < e; ++k) loss += losses[k];
  return {grad, at::full({1}, loss, in.u.options().dtype(at::kDouble))};
}

}  // namespace native
}  // namespace droidw

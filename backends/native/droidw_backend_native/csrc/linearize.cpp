// The fused linearisation of one depth frame's out-edges and its Schur Grams (DROID-W Eq. 4-5, edge form of
// droidw_cli.ba.schur).  For edge k (frame i = n -> j), pixel p, component c of r = p*_ij - p_ij and
//   w = weight_ij flow_weight_scale valid f(u_i(p)) [f(u_j(p_ij)) if bidirectional]
// one pass over the pixels gives
//   H_j[k] = sum_p sum_c w J J^T,  g_j[k] = sum_p sum_c w J r,  cost_k = sum_p sum_c w r^2   (J: pose j, focal rows)
//   e_k(p) = sum_c w J dp/dd,  C_n(p) += sum_c w (dp/dd)^2,  w_n(p) += sum_c w (dp/dd) r
// then C_n and w_n get the disparity prior gamma_d (d - D)^2 (where D > 0) and the damping, and
//   Gram = sum_p a a^T / C_n(p),  a = [e_k (k in out(n)); w_n]
// holds Gamma_kl = sum_p e_k C^-1 e_l^T and sum_p e_k C^-1 w, from which ba_step.cpp assembles S and the rhs.
//
// Sums: per tile of kTile pixels in float32 (vectorised, in a fixed order), tiles added in float64 in order.
#include "native_ba.h"

namespace droidw {
namespace native {
namespace {

// Upper-triangle slot of (a, b), a <= b, in an n x n matrix stored row by row.
inline int upper(int a, int b, int n) { return a * n - a * (a - 1) / 2 + (b - a); }

template <int KJ>
void linearize_edge(const StepConfig& cfg, const StepInputs& in, int64_t k, int height, int width,
                    EdgeSums& sums, float* er, double* cacc, double* wacc) {
  constexpr int R = KJ + 1;  // Jacobian rows and the residual
  constexpr int kSlots = R * (R + 1) / 2;
  const int hw = height * width;
  const int64_t fi = in.ii.data_ptr<int64_t>()[k], fj = in.jj.data_ptr<int64_t>()[k];
  const float* g = in.rel.data_ptr<float>() + k * kRelStride;
  const float* disp = in.disps.data_ptr<float>() + fi * hw;
  // target, weight (E, H, W, 2) with any strides (the tracker's and the synthetic edges are views)
  const float* target = in.target.data_ptr<float>() + k * in.target.stride(0);
  const float* weight = in.weight.data_ptr<float>() + k * in.weight.stride(0);
  const int64_t ts1 = in.target.stride(1), ts2 = in.target.stride(2), ts3 = in.target.stride(3);
  const int64_t ws1 = in.weight.stride(1), ws2 = in.weight.stride(2), ws3 = in.weight.stride(3);
  const float* umap = in.umap.defined() ? in.umap.data_ptr<float>() : nullptr;
  const Pinhole cam{cfg.fx, cfg.fy, cfg.cx, cfg.cy};
  const bool depth = !cfg.motion_only;

  double acc[kSlots] = {0.0};
  alignas(64) float au[R][kTile], av[R][kTile], bu[R][kTile], bv[R][kTile];  // J, r and w J, w r per component
  alignas(64) float jdu[kTile], jdv[kTile], wu[kTile], wv[kTile];
  for (int p0 = 0; p0 < hw; p0 += kTile) {
    const int n = std::min(kTile, hw - p0);
    for (int t = 0; t < n; ++t) {
      const int p = p0 + t;
      const float d = disp[p];
      const int pu = p % width, pv = p / width;
      const Projected o = project_pixel(g, cam, pu, pv, d, cfg.min_depth);
      float scale = o.valid ? cfg.flow_weight_scale : 0.0f;
      if (umap != nullptr) {
        scale *= weight_factor(umap[fi * hw + p], cfg.uncertainty_mode);
        if (cfg.bidirectional)
          scale *= weight_factor(bilinear_sample(umap + fj * hw, bilinear_corners(o.px, o.py, height, width)),
                                 cfg.uncertainty_mode);
      }
      const float* wp = weight + pv * ws1 + pu * ws2;
      const float* tp = target + pv * ts1 + pu * ts2;
      wu[t] = wp[0] * scale;
      wv[t] = wp[ws3] * scale;
      float ju[KJ], jv[KJ];
      jacobian_rows<KJ>(o, g, cam, cfg.focal_mode, d, ju, jv);
      for (int a = 0; a < KJ; ++a) {
        au[a][t] = ju[a];
        av[a][t] = jv[a];
      }
      au[KJ][t] = tp[0] - o.px;
      av[KJ][t] = tp[ts3] - o.py;
      depth_derivative(o, g, cam, jdu[t], jdv[t]);
    }
    for (int a = 0; a < R; ++a) {
#pragma omp simd
      for (int t = 0; t < n; ++t) {
        bu[a][t] = wu[t] * au[a][t];
        bv[a][t] = wv[t] * av[a][t];
      }
    }
    for (int a = 0; a < R; ++a) {
      for (int b = a; b < R; ++b) {
        float s = 0.0f;
#pragma omp simd reduction(+ : s)
        for (int t = 0; t < n; ++t) s += bu[a][t] * au[b][t] + bv[a][t] * av[b][t];
        acc[upper(a, b, R)] += s;
      }
    }
    if (!depth) continue;
    for (int a = 0; a < KJ; ++a) {
      float* row = er + static_cast<int64_t>(a) * hw + p0;
#pragma omp simd
      for (int t = 0; t < n; ++t) row[t] = bu[a][t] * jdu[t] + bv[a][t] * jdv[t];
    }
    for (int t = 0; t < n; ++t) {
      cacc[p0 + t] += wu[t] * jdu[t] * jdu[t] + wv[t] * jdv[t] * jdv[t];
      wacc[p0 + t] += bu[KJ][t] * jdu[t] + bv[KJ][t] * jdv[t];
    }
  }
  for (int a = 0; a < KJ; ++a) {
    for (int b = a; b < KJ; ++b) sums.hess[a * KJ + b] = sums.hess[b * KJ + a] = acc[upper(a, b, R)];
    sums.grad[a] = acc[upper(a, KJ, R)];
  }
  sums.cost = acc[upper(KJ, KJ, R)];
}

// C_n = sum + prior + damping, w_n = sum + prior pull; returns the prior cost sum gamma_d (d - D)^2.
double depth_terms(const StepConfig& cfg, const StepInputs& in, int64_t frame, int hw, const double* cacc,
                   const double* wacc, float* cinv, float* wtot) {
  const float* d = in.disps.data_ptr<float>() + frame * hw;
  const float* prior = in.prior.defined() ? in.prior.data_ptr<float>() + frame * hw : nullptr;
  double prior_cost = 0.0;
  for (int p = 0; p < hw; ++p) {
    double c = cacc[p], w = wacc[p];
    if (prior != nullptr) {
      const bool has = prior[p] > 0.0f;
      const double gam = has ? cfg.gamma_depth : 0.0;
      c += gam + (has ? cfg.prior_damping : cfg.depth_damping);
      w += gam * (static_cast<double>(prior[p]) - d[p]);
      prior_cost += gam * (static_cast<double>(d[p]) - prior[p]) * (static_cast<double>(d[p]) - prior[p]);
    } else {
      c += cfg.depth_damping;
    }
    cinv[p] = static_cast<float>(1.0 / c);
    wtot[p] = static_cast<float>(w);
  }
  return prior_cost;
}

// Gram = sum_p a a^T C^-1 over the rows a = [e_k (KJ rows per edge); w_n] (upper triangle, mirrored).
void schur_gram(const int64_t* edges, int count, int kj, int hw, const float* erows, const float* cinv,
                const float* wtot, std::vector<double>& gram) {
  const int rows = count * kj + 1;
  std::vector<const float*> row(rows);
  for (int c = 0; c < count; ++c)
    for (int a = 0; a < kj; ++a) row[c * kj + a] = erows + (edges[c] * kj + a) * static_cast<int64_t>(hw);
  row[rows - 1] = wtot;
  gram.assign(static_cast<size_t>(rows) * rows, 0.0);
  std::vector<float> scaled(static_cast<size_t>(rows) * kTile);
  for (int p0 = 0; p0 < hw; p0 += kTile) {
    const int n = std::min(kTile, hw - p0);
    for (int m = 0; m < rows; ++m) {
      float* dst = scaled.data() + static_cast<size_t>(m) * kTile;
      const float* src = row[m] + p0;
#pragma omp simd
      for (int t = 0; t < n; ++t) dst[t] = src[t] * cinv[p0 + t];
    }
    for (int a = 0; a < rows; ++a) {
      const float* sa = scaled.data() + static_cast<size_t>(a) * kTile;
      for (int b = a; b < rows; ++b) {
        const float* rb = row[b] + p0;
        float s = 0.0f;
#pragma omp simd reduction(+ : s)
        for (int t = 0; t < n; ++t) s += sa[t] * rb[t];
        gram[static_cast<size_t>(a) * rows + b] += s;
      }
    }
  }
  for (int a = 0; a < rows; ++a)
    for (int b = 0; b < a; ++b) gram[static_cast<size_t>(a) * rows + b] = gram[static_cast<size_t>(b) * rows + a];
}

}  // namespace

void linearize_frame(const StepConfig& cfg, const StepInputs& in, int kj, int64_t frame, const int64_t* edges,
                     int count, EdgeSums* sums, float* erows, float* cinv, float* wtot, FrameSystem& out) {
  const int height = static_cast<int>(in.disps.size(1)), width = static_cast<int>(in.disps.size(2));
  const int hw = height * width;
  const bool depth = !cfg.motion_only;
  std::vector<double> cacc(depth ? hw : 0, 0.0), wacc(depth ? hw : 0, 0.0);
  for (int c = 0; c < count; ++c) {
    const int64_t k = edges[c];
    float* er = depth ? erows + k * kj * static_cast<int64_t>(hw) : nullptr;
    if (kj == kPoseDof) linearize_edge<kPoseDof>(cfg, in, k, height, width, sums[k], er, cacc.data(), wacc.data());
    else if (kj == kPoseDof + 1)
      linearize_edge<kPoseDof + 1>(cfg, in, k, height, width, sums[k], er, cacc.data(), wacc.data());
    else linearize_edge<kMaxKJ>(cfg, in, k, height, width, sums[k], er, cacc.data(), wacc.data());
  }
  if (!depth) return;
  float* ci = cinv + frame * hw;
  float* wt = wtot + frame * hw;
  out.prior_cost = depth_terms(cfg, in, frame, hw, cacc.data(), wacc.data(), ci, wt);
  schur_gram(edges, count, kj, hw, erows, ci, wt, out.gram);
}

}  // namespace native
}  // namespace droidw

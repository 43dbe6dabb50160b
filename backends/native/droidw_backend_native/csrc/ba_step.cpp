// One damped Gauss-Newton step on poses (+ log-focal) and disparities (DROID-W Eq. 4-5), edge form of
// droidw_cli.ba.schur.  Per edge k the full Jacobian rows are T_k [J_j; J_f] with
//   T_k = [[-Ad(G_ij)^T, 0], [I_6, 0], [0, I_nf]]   (K = 12 + nf rows: pose i, pose j, focal),
// so with the per-frame sums of linearize.cpp
//   S   = sum_k T_k H_j[k] T_k^T - sum_n sum_{k,l in out(n)} T_k Gamma_kl T_l^T
//   rhs = sum_k T_k g_j[k]      - sum_n sum_{k in out(n)} T_k sum_p e_k C^-1 w
// scattered to the active nodes (poses >= t0 in an edge, and the focal node), damped
// diag += rel diag + abs (the focal block's padding rows get a unit diagonal), solved by a float64 Cholesky;
// then Delta d_n = C_n^-1 (w_n - sum_{k in out(n)} e_k^T T_k^T [dxi_i; dxi_j; df]) and d <- max(d + Delta d, min_disp).
// The pose update T <- Exp(dxi) T and the focal update are left to Python (shared with the other backends).
//
// Threads: frames are linearised in parallel (at::parallel_for over frames, each frame by one thread), and the
// assembly runs in edge and frame order, so the result does not depend on the number of threads.
#include "native_ba.h"

#include <ATen/ops/cholesky_solve.h>
#include <ATen/ops/empty.h>
#include <ATen/ops/empty_like.h>
#include <ATen/ops/full.h>
#include <ATen/ops/linalg_cholesky_ex.h>
#include <ATen/ops/zeros.h>

#include <cmath>
#include <cstring>

namespace droidw {
namespace native {
namespace {

// T_k (K x kj, row-major) of the relative pose g (R row-major, t), in float64.
void edge_transform(const float* g, int kj, double* tmat) {
  const int K = kPoseDof + kj;
  std::memset(tmat, 0, sizeof(double) * K * kj);
  double R[3][3], S[3][3], TR[3][3];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R[r][c] = g[3 * r + c];
  const double t0 = g[9], t1 = g[10], t2 = g[11];
  S[0][0] = 0; S[0][1] = -t2; S[0][2] = t1;
  S[1][0] = t2; S[1][1] = 0; S[1][2] = -t0;
  S[2][0] = -t1; S[2][1] = t0; S[2][2] = 0;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) TR[r][c] = S[r][0] * R[0][c] + S[r][1] * R[1][c] + S[r][2] * R[2][c];
  double ad[6][6] = {{0.0}};  // Ad = [[R, [t]x R], [0, R]] in the [v, w] ordering
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      ad[r][c] = R[r][c];
      ad[r][c + 3] = TR[r][c];
      ad[r + 3][c + 3] = R[r][c];
    }
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) tmat[r * kj + c] = -ad[c][r];
  for (int r = 0; r < kj; ++r) tmat[(kPoseDof + r) * kj + r] = 1.0;
}

// out (K x K) = T a T^T for a (kj x kj) with row stride `stride`, or out (K) = T a for a vector (cols = 1).
void sandwich(const double* ta, const double* a, const double* tb, int kj, int stride, double* out) {
  const int K = kPoseDof + kj;
  double tmp[(kPoseDof + kMaxKJ) * kMaxKJ];
  for (int r = 0; r < K; ++r)
    for (int c = 0; c < kj; ++c) {
      double s = 0.0;
      for (int m = 0; m < kj; ++m) s += ta[r * kj + m] * a[m * stride + c];
      tmp[r * kj + c] = s;
    }
  for (int r = 0; r < K; ++r)
    for (int c = 0; c < K; ++c) {
      double s = 0.0;
      for (int m = 0; m < kj; ++m) s += tmp[r * kj + m] * tb[c * kj + m];
      out[r * K + c] = s;
    }
}

// Where row r of an edge's K rows goes in S: slot * 6 + offset, or -1 for an inactive node.
struct RowMap {
  int64_t index[kPoseDof + kMaxKJ];
};

RowMap row_map(int64_t fi, int64_t fj, int64_t focal_node, int kj, const int64_t* slot) {
  RowMap m;
  const int K = kPoseDof + kj;
  for (int r = 0; r < K; ++r) {
    const int64_t node = r < kPoseDof ? fi : (r < 2 * kPoseDof ? fj : focal_node);
    const int64_t s = slot[node];
    m.index[r] = s < 0 ? -1 : s * kPoseDof + r % kPoseDof;
  }
  return m;
}

void check(const at::Tensor& t, const char* name, at::ScalarType type) {
  TORCH_CHECK(t.device().is_cpu(), name, " must be a CPU tensor");
  TORCH_CHECK(t.is_contiguous(), name, " must be contiguous");
  TORCH_CHECK(t.scalar_type() == type, name, " has the wrong dtype");
}

}  // namespace

std::vector<at::Tensor> ba_step(const StepConfig& cfg, const StepInputs& in) {
  check(in.rel, "rel", at::kFloat);
  check(in.disps, "disps", at::kFloat);
  check(in.ii, "ii", at::kLong);
  check(in.jj, "jj", at::kLong);
  for (const auto& [t, name] : {std::pair{in.target, "target"}, std::pair{in.weight, "weight"}}) {
    TORCH_CHECK(t.device().is_cpu() && t.scalar_type() == at::kFloat && t.dim() == 4, name,
                " must be a float32 CPU tensor (E, H, W, 2)");
  }
  check(in.slot, "slot", at::kLong);
  if (in.umap.defined()) check(in.umap, "umap", at::kFloat);
  if (in.prior.defined()) check(in.prior, "prior", at::kFloat);
  TORCH_CHECK(in.disps.dim() == 3, "disps must be (N, H, W)");
  const int64_t n = in.disps.size(0), hw = in.disps.size(1) * in.disps.size(2);
  const int64_t e = in.ii.size(0);
  const int nf = cfg.focal_mode == kFocalShared ? 1 : (cfg.focal_mode == kFocalXY ? 2 : 0);
  const int kj = kPoseDof + nf, K = kPoseDof + kj;
  const bool depth = !cfg.motion_only;
  const int64_t* ii = in.ii.data_ptr<int64_t>();
  const int64_t* jj = in.jj.data_ptr<int64_t>();
  const int64_t* slot = in.slot.data_ptr<int64_t>();
  const int64_t num_nodes = in.slot.size(0);
  int64_t active = 0;
  for (int64_t m = 0; m < num_nodes; ++m) active += slot[m] >= 0;

  // the out-edges of every frame, in edge order
  std::vector<int64_t> start(n + 1, 0), order(e);
  for (int64_t k = 0; k < e; ++k) ++start[ii[k] + 1];
  for (int64_t f = 0; f < n; ++f) start[f + 1] += start[f];
  {
    std::vector<int64_t> fill(start.begin(), start.end() - 1);
    for (int64_t k = 0; k < e; ++k) order[fill[ii[k]]++] = k;
  }

  std::vector<EdgeSums> sums(e);
  std::vector<FrameSystem> frames(n);
  at::Tensor erows = depth ? at::empty({e, kj, hw}, in.disps.options()) : at::Tensor();
  at::Tensor cinv = at::empty({n, hw}, in.disps.options()), wtot = at::empty({n, hw}, in.disps.options());
  float* er = depth ? erows.data_ptr<float>() : nullptr;
  at::parallel_for(0, n, 1, [&](int64_t lo, int64_t hi) {
    for (int64_t f = lo; f < hi; ++f)
      linearize_frame(cfg, in, kj, f, order.data() + start[f], static_cast<int>(start[f + 1] - start[f]),
                      sums.data(), er, cinv.data_ptr<float>(), wtot.data_ptr<float>(), frames[f]);
  });
  double cost = 0.0;
  for (int64_t k = 0; k < e; ++k) cost += sums[k].cost;
  if (depth)
    for (int64_t f = 0; f < n; ++f) cost += frames[f].prior_cost;

  auto f64 = in.disps.options().dtype(at::kDouble);
  at::Tensor node_dx = at::zeros({num_nodes, kPoseDof}, f64);
  auto finish = [&](bool solved, at::Tensor disps) {
    return std::vector<at::Tensor>{node_dx, disps, at::full({1}, cost, f64),
                                      at::full({1}, solved, in.disps.options().dtype(at::kBool))};
  };
  if (active == 0) return finish(true, in.disps.clone());

  // assemble S and the rhs (edge order, then frame order)
  const int64_t dim = active * kPoseDof;
  at::Tensor s_mat = at::zeros({dim, dim}, f64), rhs = at::zeros({dim, 1}, f64);
  double* S = s_mat.data_ptr<double>();
  double* b = rhs.data_ptr<double>();
  std::vector<double> tmats(static_cast<size_t>(e) * K * kj);
  std::vector<RowMap> maps(e);
  double block[(kPoseDof + kMaxKJ) * (kPoseDof + kMaxKJ)];
  for (int64_t k = 0; k < e; ++k) {
    double* t = tmats.data() + k * K * kj;
    edge_transform(in.rel.data_ptr<float>() + k * kRelStride, kj, t);
    maps[k] = row_map(ii[k], jj[k], n, kj, slot);
    sandwich(t, sums[k].hess, t, kj, kj, block);
    for (int r = 0; r < K; ++r) {
      const int64_t ri = maps[k].index[r];
      if (ri < 0) continue;
      double g = 0.0;
      for (int m = 0; m < kj; ++m) g += t[r * kj + m] * sums[k].grad[m];
      b[ri] += g;
      for (int c = 0; c < K; ++c)
        if (maps[k].index[c] >= 0) S[ri * dim + maps[k].index[c]] += block[r * K + c];
    }
  }
  if (depth) {
    for (int64_t f = 0; f < n; ++f) {
      const int count = static_cast<int>(start[f + 1] - start[f]);
      const int rows = count * kj + 1;
      const double* gram = frames[f].gram.data();
      for (int a = 0; a < count; ++a) {
        const int64_t ka = order[start[f] + a];
        const double* ta = tmats.data() + ka * K * kj;
        for (int r = 0; r < K; ++r) {  // rhs -= T_k sum_p e_k C^-1 w
          const int64_t ri = maps[ka].index[r];
          if (ri < 0) continue;
          double g = 0.0;
          for (int m = 0; m < kj; ++m) g += ta[r * kj + m] * gram[(a * kj + m) * rows + rows - 1];
          b[ri] -= g;
        }
        for (int c = 0; c < count; ++c) {  // S -= T_k Gamma_kl T_l^T
          const int64_t kc = order[start[f] + c];
          sandwich(ta, gram + (a * kj) * rows + c * kj, tmats.data() + kc * K * kj, kj, rows, block);
          for (int r = 0; r < K; ++r) {
            const int64_t ri = maps[ka].index[r];
            if (ri < 0) continue;
            for (int q = 0; q < K; ++q)
              if (maps[kc].index[q] >= 0) S[ri * dim + maps[kc].index[q]] -= block[r * K + q];
          }
        }
      }
    }
  }
  for (int64_t r = 0; r < dim; ++r) S[r * dim + r] += cfg.pose_damping_rel * S[r * dim + r] + cfg.pose_damping_abs;
  if (nf > 0 && slot[n] >= 0)
    for (int r = nf; r < kPoseDof; ++r) S[(slot[n] * kPoseDof + r) * (dim + 1)] = 1.0;

  auto [chol, info] = at::linalg_cholesky_ex(s_mat);
  if (info.item<int>() != 0) return finish(false, in.disps.clone());
  const at::Tensor dx = at::cholesky_solve(rhs, chol).contiguous();
  const double* x = dx.data_ptr<double>();
  for (int64_t r = 0; r < dim; ++r)
    if (!std::isfinite(x[r])) return finish(false, in.disps.clone());
  double* nd = node_dx.data_ptr<double>();
  for (int64_t m = 0; m < num_nodes; ++m)
    if (slot[m] >= 0)
      for (int r = 0; r < kPoseDof; ++r) nd[m * kPoseDof + r] = x[slot[m] * kPoseDof + r];
  if (!depth) return finish(true, in.disps.clone());

  // back-substitution, per frame
  at::Tensor out = at::empty_like(in.disps);
  const double* ndx = node_dx.data_ptr<double>();
  at::parallel_for(0, n, 1, [&](int64_t lo, int64_t hi) {
    std::vector<float> back(hw);
    for (int64_t f = lo; f < hi; ++f) {
      std::fill(back.begin(), back.end(), 0.0f);
      for (int64_t c = start[f]; c < start[f + 1]; ++c) {
        const int64_t k = order[c];
        double x[kPoseDof + kMaxKJ];
        for (int r = 0; r < K; ++r) {
          const int64_t node = r < kPoseDof ? ii[k] : (r < 2 * kPoseDof ? jj[k] : n);
          x[r] = ndx[node * kPoseDof + r % kPoseDof];
        }
        const double* t = tmats.data() + k * K * kj;
        for (int a = 0; a < kj; ++a) {  // delta = T_k^T x
          double s = 0.0;
          for (int r = 0; r < K; ++r) s += t[r * kj + a] * x[r];
          const float da = static_cast<float>(s);
          const float* row = er + (k * kj + a) * hw;
#pragma omp simd
          for (int64_t p = 0; p < hw; ++p) back[p] += da * row[p];
        }
      }
      const float* d = in.disps.data_ptr<float>() + f * hw;
      const float* ci = cinv.data_ptr<float>() + f * hw;
      const float* wt = wtot.data_ptr<float>() + f * hw;
      float* o = out.data_ptr<float>() + f * hw;
      for (int64_t p = 0; p < hw; ++p) o[p] = std::max(d[p] + ci[p] * (wt[p] - back[p]), cfg.min_disp);
    }
  });
  return finish(true, out);
}

}  // namespace native
}  // namespace droidw

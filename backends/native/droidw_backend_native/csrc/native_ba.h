// droidw native CPU backend: settings, inputs and entry points shared by the binding and the kernels.
//
// Conventions match droidw_backend_cpu (and the CUDA backend's csrc/droidw_ba.h):
//   rel      (E, 12) float32: G_ij = G_j G_i^-1 as R (row-major, 9) then t (3)
//   disps    (N, HW) float32, pixel p = v * W + u sits at x = u, y = v
//   target, weight (E, HW, 2) float32 (x, y)
//   umap     (N, HW) float32, the u the BA weighting sees (already rescaled for the "relative" mode)
//   features (N, HW, C) float32 (channels-last rows)
// Only the binding includes torch/extension.h; the kernels use the ATen core headers (a much shorter build).
// Every sum over pixels is accumulated per frame or per edge by one thread in a fixed order (float32 sums
// over tiles of kTile pixels, float64 across tiles and edges), so results do not depend on the thread count.
#pragma once

#include <ATen/Parallel.h>
#include <ATen/core/Tensor.h>

#include <vector>

#include "droidw_pixel.h"

namespace droidw {
namespace native {

constexpr int kTile = 64;           // pixels per tile of the fused per-pixel loops
constexpr int kMaxKJ = kPoseDof + kMaxFocalDof;

// Scalar settings of one Gauss-Newton step (droidw_cli.ba.params.BAParams).
struct StepConfig {
  float fx = 0, fy = 0, cx = 0, cy = 0;
  float min_depth = 0.05f;
  float flow_weight_scale = 1e-3f;
  int uncertainty_mode = kUncertaintyOff;  // off when umap is undefined
  bool bidirectional = false;
  int focal_mode = kFocalNone;
  bool motion_only = false;
  double gamma_depth = 1e-3, depth_damping = 1e-7, prior_damping = 1e-4;
  double pose_damping_rel = 1e-4, pose_damping_abs = 0.1;
  float min_disp = 1e-3f;
};

// Tensor inputs of one step; umap and prior may be undefined; target, weight (E, H, W, 2) may be strided views.  slot (M,) int64: node -> active slot or -1
// (nodes 0..N-1 are poses, node N the focal node when one is optimised).
struct StepInputs {
  at::Tensor rel, disps, ii, jj, target, weight, umap, prior, slot;
};

// Scalar settings of the uncertainty data term (droidw_cli.ba.uncertainty).
struct SimilarityConfig {
  float fx = 0, fy = 0, cx = 0, cy = 0;
  float min_depth = 0.05f;
  float gamma_data = 0.1f;
  float sim_threshold = 0.5f;
  float geo_sigma = 0.0f;  // > 0: s *= exp(-(r / geo_sigma)^2), r = |target - p_ij| (grid px)
};

// Tensor inputs of the data term (E_sim edges only); target (K, HW, 2) is used when geo_sigma > 0.
struct SimilarityInputs {
  at::Tensor rel, disps, ii, jj, omega, features, norms, u, target;
};

// One edge's share of a frame's linearisation (see linearize.cpp).
struct EdgeSums {
  double hess[kMaxKJ * kMaxKJ];  // H_j = sum_p sum_c w J J^T (pose j and focal rows), KJ x KJ
  double grad[kMaxKJ];           // g_j = sum_p sum_c w J r
  double cost;                   // sum_p sum_c w r^2
};

// The linearisation of the out-edges of one frame n and its Schur Grams: fills sums[k] for each edge k of
// `edges`, erows[k] (KJ, HW), and, with depth, cinv (HW) = 1 / C_n, wtot (HW) = w_n (damping and prior in),
// gram ((D KJ + 1)^2) = sum_p a a^T C^-1 with a = [e_k (k in edges); w_n], and the prior cost.
struct FrameSystem {
  std::vector<double> gram;
  double prior_cost = 0.0;
};

void linearize_frame(const StepConfig& cfg, const StepInputs& in, int kj, int64_t frame, const int64_t* edges,
                     int count, EdgeSums* sums, float* erows, float* cinv, float* wtot, FrameSystem& out);

// Returns {node_dx (M, 6) float64, disps (N, H, W) float32, cost (1) float64, solved (1) bool}.
std::vector<at::Tensor> ba_step(const StepConfig& cfg, const StepInputs& in);

// Returns {grad (N, HW) float32 = d(gamma_data E_sim)/du, loss (1) float64}.
std::vector<at::Tensor> similarity(const SimilarityConfig& cfg, const SimilarityInputs& in);

// Returns {coords (E, H, W, 2) float32, valid (E, H, W) bool} (Eq. 1).
std::vector<at::Tensor> reproject(at::Tensor rel, at::Tensor disps, at::Tensor intrinsics,
                                     at::Tensor ii, double min_depth);

}  // namespace native
}  // namespace droidw

// droidw CUDA backend: parameter structs shared by the binding (.cpp) and the kernels (.cu).
//
// Conventions match droidw_cli.geometry.projection / droidw_backend_cpu:
//   rel     (E, 12) float32: G_ij = G_j G_i^-1 as R (row-major, 9) then t (3)
//   disps   (N, HW) float32, pixel p = v * W + u sits at x = u, y = v
//   target, weight (E, HW, 2) float32 (x, y)
//   features (N, C, HW) float32
// Every Jacobian row count is KJ = 6 + nf (pose j twist [v, w] then log-focal rows).
#pragma once

#include <torch/extension.h>

// The constants, enums and per-pixel maths shared with the native CPU backend (droidw_cli/ba/csrc): the clamp
// weighting's constants, kCosEps, kPoseDof, kMaxFocalDof, kRelStride, UncertaintyMode, FocalMode and the
// DROIDW_HD (__host__ __device__) functions the kernels call.
#include "droidw_pixel.h"

namespace droidw {

// Scalar settings of one linearisation (see droidw_cli.ba.params.BAParams).
struct LinearizeConfig {
  float fx = 0, fy = 0, cx = 0, cy = 0;
  float min_depth = 0.05f;
  float flow_weight_scale = 1e-3f;
  int uncertainty_mode = kUncertaintyOff;
  bool bidirectional = false;
  int focal_mode = kFocalNone;
  bool with_depth = true;  // false = motion-only: no E rows, C or w
};

// Scalar settings of one uncertainty data term (see droidw_cli.ba.uncertainty).
struct SimilarityConfig {
  float fx = 0, fy = 0, cx = 0, cy = 0;
  float min_depth = 0.05f;
  float gamma_data = 0.1f;
  float sim_threshold = 0.5f;
  float geo_sigma = 0.0f;  // > 0: s *= exp(-(r / geo_sigma)^2), r = |target - p_ij| (grid px)
};

// Tensor inputs of the linearisation; umap may be undefined (unweighted BA).
struct LinearizeInputs {
  torch::Tensor rel, disps, ii, jj, target, weight, umap;
};

// Tensor inputs of the uncertainty data term (sim edges only).
struct SimilarityInputs {
  torch::Tensor rel, disps, ii, jj, omega, features, u, target;  // target (K, HW, 2), used when geo_sigma > 0
};

// Returns {hess_j (E, KJ, KJ) float64, grad_j (E, KJ) float64, erows (E, KJ, HW) float32 or undefined,
//          cdiag (N, HW) float32 or undefined, wvec (N, HW) float32 or undefined, cost (1) float64};
// the sums over pixels are float64 in a fixed order (linearize.cu).
std::vector<torch::Tensor> linearize_cuda(const LinearizeConfig& cfg, const LinearizeInputs& in);

// Returns {grad (N, HW) = d(gamma_data E_sim)/du, loss (1)}.
std::vector<torch::Tensor> similarity_cuda(const SimilarityConfig& cfg, const SimilarityInputs& in);

}  // namespace droidw

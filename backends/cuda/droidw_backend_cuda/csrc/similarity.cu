// Uncertainty data term gamma_data * E_sim and its d/du map (droidw_cli.ba.uncertainty):
//   t = omega_k gamma_data valid (1 - s) / (u_i u_ij),  G[i, p] -= t / u_i,  G[j, corner c] -= w_c t / u_ij
// One thread per (sim edge, pixel); features (N, C, HW) are read channel by channel.
#include <c10/cuda/CUDAException.h>
#include <c10/cuda/CUDAStream.h>
#include <c10/cuda/CUDAGuard.h>

#include "geometry.cuh"

namespace droidw {
namespace {

__global__ void similarity_kernel(SimilarityConfig cfg, int hw, int height, int width, int channels,
                                  const float* __restrict__ rel, const float* __restrict__ disps,
                                  const int64_t* __restrict__ ii, const int64_t* __restrict__ jj,
                                  const float* __restrict__ omega, const float* __restrict__ feats,
                                  const float* __restrict__ u, const float* __restrict__ target,
                                  double* __restrict__ grad, double* __restrict__ loss) {
  const int e = blockIdx.y;
  const int p = blockIdx.x * blockDim.x + threadIdx.x;
  float t = 0.0f;
  if (p < hw) {
    const int64_t fi = ii[e], fj = jj[e];
    const Pinhole k{cfg.fx, cfg.fy, cfg.cx, cfg.cy};
    const Projected o = project_pixel(rel + static_cast<int64_t>(e) * kRelStride, k, p % width, p / width,
                                      disps[fi * hw + p], cfg.min_depth);
    const bool valid = o.valid && inside_image(o.px, o.py, height, width);
    const Bilinear b = bilinear_corners(o.px, o.py, height, width);
    const float* fi_ptr = feats + fi * channels * hw;
    const float* fj_ptr = feats + fj * channels * hw;
    float dot = 0.0f, ni = 0.0f, nij = 0.0f;
    for (int c = 0; c < channels; ++c) {
      const float a = fi_ptr[static_cast<int64_t>(c) * hw + p];
      const float* row = fj_ptr + static_cast<int64_t>(c) * hw;
      const float s = b.w[0] * row[b.idx[0]] + b.w[1] * row[b.idx[1]] + b.w[2] * row[b.idx[2]] + b.w[3] * row[b.idx[3]];
      dot += a * s;
      ni += a * a;
      nij += s * s;
    }
    const float cosv = dot / fmaxf(sqrtf(nij) * sqrtf(ni), kCosEps);
    float residual = -1.0f;  // |target - p_ij|, only for the geometric factor
    if (target != nullptr && cfg.geo_sigma > 0.0f) {
      const float* tp = target + (static_cast<int64_t>(e) * hw + p) * 2;
      residual = hypotf(tp[0] - o.px, tp[1] - o.py);
    }
    const float sim = similarity_score(cosv, cfg.sim_threshold, residual, cfg.geo_sigma);
    const float ui = u[fi * hw + p];
    const float uij = bilinear_sample(u + fj * hw, b);
    t = similarity_term(sim, valid, cfg.gamma_data * omega[e], ui, uij);
    if (t != 0.0f) {
      atomicAdd(grad + fi * hw + p, static_cast<double>(-t / ui));
      const float gij = -t / uij;
#pragma unroll
      for (int c = 0; c < 4; ++c) atomicAdd(grad + fj * hw + b.idx[c], static_cast<double>(b.w[c] * gij));
    }
  }
  __shared__ float partial[kThreads / kWarp];
  const float s = warp_sum(t);
  if (threadIdx.x % kWarp == 0) partial[threadIdx.x / kWarp] = s;
  __syncthreads();
  if (threadIdx.x == 0) {
    double total = 0.0;
    for (int w = 0; w < static_cast<int>(blockDim.x) / kWarp; ++w) total += partial[w];
    atomicAdd(loss, total);
  }
}

void check(const torch::Tensor& t, const char* name, at::ScalarType type) {
  TORCH_CHECK(t.is_cuda(), name, " must be a CUDA tensor");
  TORCH_CHECK(t.is_contiguous(), name, " must be contiguous");
  TORCH_CHECK(t.scalar_type() == type, name, " has the wrong dtype");
}

}  // namespace

std::vector<torch::Tensor> similarity_cuda(const SimilarityConfig& cfg, const SimilarityInputs& in) {
  check(in.rel, "rel", at::kFloat);
  check(in.disps, "disps", at::kFloat);
  check(in.ii, "ii", at::kLong);
  check(in.jj, "jj", at::kLong);
  check(in.omega, "omega", at::kFloat);
  check(in.features, "features", at::kFloat);
  check(in.u, "u", at::kFloat);
  TORCH_CHECK(in.features.dim() == 4, "features must be (N, C, H, W)");
  const bool with_target = cfg.geo_sigma > 0.0f;
  if (with_target) {
    check(in.target, "target", at::kFloat);
    TORCH_CHECK(in.target.size(0) == in.ii.size(0), "target must have one row per sim edge");
  }
  TORCH_CHECK(in.ii.size(0) <= kMaxGridY, "too many edges for one launch");
  const c10::cuda::CUDAGuard guard(in.disps.device());
  const int n = static_cast<int>(in.features.size(0)), channels = static_cast<int>(in.features.size(1));
  const int height = static_cast<int>(in.features.size(2)), width = static_cast<int>(in.features.size(3));
  const int hw = height * width;
  // float64 sums: the atomics' order varies from run to run, and float64 sums of float32 terms
  // rounded once to float32 give the same result in any order (but for ties at a rounding boundary)
  auto grad = torch::zeros({n, static_cast<int64_t>(hw)}, in.u.options().dtype(at::kDouble));
  auto loss = torch::zeros({1}, in.u.options().dtype(at::kDouble));
  const int64_t edges = in.ii.size(0);
  if (edges > 0) {
    const dim3 grid((hw + kThreads - 1) / kThreads, static_cast<unsigned>(edges));
    auto stream = c10::cuda::getCurrentCUDAStream();
    similarity_kernel<<<grid, kThreads, 0, stream>>>(
        cfg, hw, height, width, channels, in.rel.data_ptr<float>(), in.disps.data_ptr<float>(),
        in.ii.data_ptr<int64_t>(), in.jj.data_ptr<int64_t>(), in.omega.data_ptr<float>(),
        in.features.data_ptr<float>(), in.u.data_ptr<float>(),
        with_target ? in.target.data_ptr<float>() : nullptr, grad.data_ptr<double>(), loss.data_ptr<double>());
    C10_CUDA_KERNEL_LAUNCH_CHECK();
  }
  return {grad.to(at::kFloat), loss.to(at::kFloat)};
}

}  // namespace droidw

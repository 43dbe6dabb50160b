// GN linearisation kernel: one thread per (edge, pixel), per-edge sums reduced
// in the block and added atomically.  Mirrors droidw_backend_cpu.linearize:
//   hess_j[e] = sum_p sum_c w J J^T,  grad_j[e] = sum_p sum_c w J r   (J = pose-j and log-focal rows)
//   erows[e, :, p] = sum_c w J dp/dd,  C[i, p] += sum_c w (dp/dd)^2,  wvec[i, p] += sum_c w (dp/dd) r
#include <c10/cuda/CUDAException.h>
#include <c10/cuda/CUDAStream.h>
#include <c10/cuda/CUDAGuard.h>

#include "geometry.cuh"

namespace droidw {
namespace {

constexpr int kPixelsPerThread = 4;  // pixel-loop length before the block reduction

template <int KJ>
struct Accum {
  static constexpr int kHess = KJ * (KJ + 1) / 2;
  static constexpr int kSize = kHess + KJ + 1;  // upper-triangular Hessian, gradient, cost
};

template <int KJ>
__global__ void linearize_kernel(LinearizeConfig cfg, int hw, int width, const float* __restrict__ rel,
                                 const float* __restrict__ disps, const int64_t* __restrict__ ii,
                                 const int64_t* __restrict__ jj, const float* __restrict__ target,
                                 const float* __restrict__ weight, const float* __restrict__ umap,
                                 int height, float* __restrict__ hess_j, float* __restrict__ grad_j,
                                 float* __restrict__ erows, float* __restrict__ cdiag, float* __restrict__ wvec,
                                 float* __restrict__ cost) {
  constexpr int kSize = Accum<KJ>::kSize;
  constexpr int kHess = Accum<KJ>::kHess;
  const int e = blockIdx.y;
  const int64_t fi = ii[e], fj = jj[e];
  const float* g = rel + static_cast<int64_t>(e) * kRelStride;
  const Pinhole k{cfg.fx, cfg.fy, cfg.cx, cfg.cy};

  float acc[kSize];
#pragma unroll
  for (int a = 0; a < kSize; ++a) acc[a] = 0.0f;

  for (int p = blockIdx.x * blockDim.x + threadIdx.x; p < hw; p += gridDim.x * blockDim.x) {
    const int u = p % width, v = p / width;
    const float d = disps[fi * hw + p];
    const Projected o = project_pixel(g, k, u, v, d, cfg.min_depth);
    const int64_t ep = static_cast<int64_t>(e) * hw + p;
    float scale = o.valid ? cfg.flow_weight_scale : 0.0f;
    if (umap != nullptr) {
      scale *= weight_factor(umap[fi * hw + p], cfg.uncertainty_mode);
      if (cfg.bidirectional) {
        const Bilinear b = bilinear_corners(o.px, o.py, height, width);
        const float* uj = umap + fj * hw;
        const float s = b.w[0] * uj[b.idx[0]] + b.w[1] * uj[b.idx[1]] + b.w[2] * uj[b.idx[2]] + b.w[3] * uj[b.idx[3]];
        scale *= weight_factor(s, cfg.uncertainty_mode);
      }
    }
    const float wu = weight[2 * ep] * scale, wv = weight[2 * ep + 1] * scale;
    const float ru = target[2 * ep] - o.px, rv = target[2 * ep + 1] - o.py;

    // pose-j rows (twist [v, w]) then log-focal rows
    const float dz = d * o.z, xy = o.x * o.y;
    float ju[KJ], jv[KJ];
    ju[0] = cfg.fx * dz;          jv[0] = 0.0f;
    ju[1] = 0.0f;                 jv[1] = cfg.fy * dz;
    ju[2] = -cfg.fx * o.x * dz;   jv[2] = -cfg.fy * o.y * dz;
    ju[3] = -cfg.fx * xy;         jv[3] = -cfg.fy * (1.0f + o.y * o.y);
    ju[4] = cfg.fx * (1.0f + o.x * o.x); jv[4] = cfg.fy * xy;
    ju[5] = -cfg.fx * o.y;        jv[5] = cfg.fy * o.x;
    if (KJ > kPoseDof) {
      const float dfx_u = o.x - o.xbar * o.z * (g[0] - o.x * g[6]);
      const float dfx_v = -(cfg.fy / cfg.fx) * o.xbar * o.z * (g[3] - o.y * g[6]);
      const float dfy_u = -(cfg.fx / cfg.fy) * o.ybar * o.z * (g[1] - o.x * g[7]);
      const float dfy_v = o.y - o.ybar * o.z * (g[4] - o.y * g[7]);
      if (cfg.focal_mode == kFocalShared) {
        ju[kPoseDof] = cfg.fx * dfx_u + cfg.fy * dfy_u;
        jv[kPoseDof] = cfg.fx * dfx_v + cfg.fy * dfy_v;
      } else {
        ju[kPoseDof] = cfg.fx * dfx_u;
        jv[kPoseDof] = cfg.fx * dfx_v;
        if (KJ > kPoseDof + 1) {
          ju[KJ - 1] = cfg.fy * dfy_u;
          jv[KJ - 1] = cfg.fy * dfy_v;
        }
      }
    }

    int slot = 0;
#pragma unroll
    for (int a = 0; a < KJ; ++a) {
#pragma unroll
      for (int b = a; b < KJ; ++b) acc[slot++] += wu * ju[a] * ju[b] + wv * jv[a] * jv[b];
    }
#pragma unroll
    for (int a = 0; a < KJ; ++a) acc[kHess + a] += ju[a] * (wu * ru) + jv[a] * (wv * rv);
    acc[kSize - 1] += wu * ru * ru + wv * rv * rv;

    if (cfg.with_depth) {
      const float t0 = g[9], t1 = g[10], t2 = g[11];
      const float jdu = cfg.fx * o.z * (t0 - o.x * t2);
      const float jdv = cfg.fy * o.z * (t1 - o.y * t2);
#pragma unroll
      for (int a = 0; a < KJ; ++a) erows[(static_cast<int64_t>(e) * KJ + a) * hw + p] = wu * ju[a] * jdu + wv * jv[a] * jdv;
      atomicAdd(cdiag + fi * hw + p, wu * jdu * jdu + wv * jdv * jdv);
      atomicAdd(wvec + fi * hw + p, wu * jdu * ru + wv * jdv * rv);
    }
  }

  // block reduction of the per-edge sums: warp shuffles, then one warp over the warps
  __shared__ float partial[kThreads / kWarp][kSize];
  const int lane = threadIdx.x % kWarp, warp = threadIdx.x / kWarp;
#pragma unroll
  for (int a = 0; a < kSize; ++a) {
    const float s = warp_sum(acc[a]);
    if (lane == 0) partial[warp][a] = s;
  }
  __syncthreads();
  const int warps = blockDim.x / kWarp;
  for (int a = threadIdx.x; a < kSize; a += blockDim.x) {
    float s = 0.0f;
    for (int w = 0; w < warps; ++w) s += partial[w][a];
    if (a < kHess) {
      // slot a -> (row, col) of the upper triangle; mirror into the lower one
      int row = 0, rem = a;
      while (rem >= KJ - row) { rem -= KJ - row; ++row; }
      const int col = row + rem;
      float* h = hess_j + static_cast<int64_t>(e) * KJ * KJ;
      atomicAdd(h + row * KJ + col, s);
      if (col != row) atomicAdd(h + col * KJ + row, s);
    } else if (a < kSize - 1) {
      atomicAdd(grad_j + static_cast<int64_t>(e) * KJ + (a - kHess), s);
    } else {
      atomicAdd(cost, s);
    }
  }
}

template <int KJ>
void launch(const LinearizeConfig& cfg, const LinearizeInputs& in, int height, int width, torch::Tensor& hess_j,
            torch::Tensor& grad_j, torch::Tensor& erows, torch::Tensor& cdiag, torch::Tensor& wvec,
            torch::Tensor& cost) {
  const int hw = height * width;
  const int edges = static_cast<int>(in.ii.size(0));
  const int per_block = kThreads * kPixelsPerThread;
  const dim3 grid((hw + per_block - 1) / per_block, edges);
  auto stream = c10::cuda::getCurrentCUDAStream();
  linearize_kernel<KJ><<<grid, kThreads, 0, stream>>>(
      cfg, hw, width, in.rel.data_ptr<float>(), in.disps.data_ptr<float>(), in.ii.data_ptr<int64_t>(),
      in.jj.data_ptr<int64_t>(), in.target.data_ptr<float>(), in.weight.data_ptr<float>(),
      in.umap.defined() ? in.umap.data_ptr<float>() : nullptr, height, hess_j.data_ptr<float>(),
      grad_j.data_ptr<float>(), cfg.with_depth ? erows.data_ptr<float>() : nullptr,
      cfg.with_depth ? cdiag.data_ptr<float>() : nullptr, cfg.with_depth ? wvec.data_ptr<float>() : nullptr,
      cost.data_ptr<float>());
  C10_CUDA_KERNEL_LAUNCH_CHECK();
}

void check(const torch::Tensor& t, const char* name, at::ScalarType type) {
  TORCH_CHECK(t.is_cuda(), name, " must be a CUDA tensor");
  TORCH_CHECK(t.is_contiguous(), name, " must be contiguous");
  TORCH_CHECK(t.scalar_type() == type, name, " has the wrong dtype");
}

}  // namespace

std::vector<torch::Tensor> linearize_cuda(const LinearizeConfig& cfg, const LinearizeInputs& in) {
  check(in.rel, "rel", at::kFloat);
  check(in.disps, "disps", at::kFloat);
  check(in.ii, "ii", at::kLong);
  check(in.jj, "jj", at::kLong);
  check(in.target, "target", at::kFloat);
  check(in.weight, "weight", at::kFloat);
  if (in.umap.defined()) check(in.umap, "umap", at::kFloat);
  TORCH_CHECK(in.disps.dim() == 3, "disps must be (N, H, W)");
  TORCH_CHECK(in.ii.size(0) <= kMaxGridY, "too many edges for one launch");
  const c10::cuda::CUDAGuard guard(in.disps.device());
  const int n = static_cast<int>(in.disps.size(0));
  const int height = static_cast<int>(in.disps.size(1)), width = static_cast<int>(in.disps.size(2));
  const int64_t edges = in.ii.size(0);
  const int nf = cfg.focal_mode == kFocalShared ? 1 : (cfg.focal_mode == kFocalXY ? 2 : 0);
  const int kj = kPoseDof + nf;
  auto opts = in.disps.options();
  auto hess_j = torch::zeros({edges, kj, kj}, opts);
  auto grad_j = torch::zeros({edges, kj}, opts);
  auto cost = torch::zeros({1}, opts);
  torch::Tensor erows, cdiag, wvec;
  if (cfg.with_depth) {
    erows = torch::empty({edges, kj, static_cast<int64_t>(height) * width}, opts);
    cdiag = torch::zeros({n, static_cast<int64_t>(height) * width}, opts);
    wvec = torch::zeros({n, static_cast<int64_t>(height) * width}, opts);
  }
  if (edges > 0) {
    if (nf == 0) launch<kPoseDof>(cfg, in, height, width, hess_j, grad_j, erows, cdiag, wvec, cost);
    else if (nf == 1) launch<kPoseDof + 1>(cfg, in, height, width, hess_j, grad_j, erows, cdiag, wvec, cost);
    else launch<kPoseDof + kMaxFocalDof>(cfg, in, height, width, hess_j, grad_j, erows, cdiag, wvec, cost);
  }
  return {hess_j, grad_j, erows, cdiag, wvec, cost};
}

}  // namespace droidw

// GN linearisation kernels, mirroring droidw_backend_cpu.linearize (edge form).  For edge e
// (frame i = ii[e] -> j = jj[e]), pixel p and component c of r = p*_ij - p_ij, weight w:
//   hess_j[e] = sum_p sum_c w J J^T,  grad_j[e] = sum_p sum_c w J r,  cost = sum_e sum_p sum_c w r^2
//   erows[e, :, p] = sum_c w J dp/dd,  C[i, p] += sum_c w (dp/dd)^2,  wvec[i, p] += sum_c w (dp/dd) r
// with J the pose-j twist [v, w] rows and the log-focal rows (KJ = 6 + nf).
//
// Precision (issue 10).  Per-pixel arithmetic is float32.  Every sum over pixels is accumulated
// in float64 and reduced in a fixed order, without atomics: each thread sums its pixels, a warp
// tree sums its lanes, the block sums its warps in order into one partial per (edge, pixel tile),
// and finish_kernel sums an edge's tiles in order.  The Schur complement B - E C^-1 E^T of a
// poorly conditioned window cancels most of B, so float32 sums (atomics in any order) moved the
// step by 4e-4 of its size; float64 sums leave only float32 per-pixel rounding, which averages
// out.  C and wvec sum over the few out-edges of a frame with float64 atomics and are rounded to
// float32 once.  The results are the same from run to run.
#include <c10/cuda/CUDAException.h>
#include <c10/cuda/CUDAStream.h>
#include <c10/cuda/CUDAGuard.h>

#include "geometry.cuh"

namespace droidw {
namespace {

constexpr int kPixelsPerThread = 4;                     // pixels per thread in one tile
constexpr int kTilePixels = kThreads * kPixelsPerThread;  // pixels per block (one tile of one edge)
constexpr int kFinishThreads = 2 * kWarp;               // >= the largest Accum<KJ>::kSize (45)

template <int KJ>
struct Accum {
  static constexpr int kHess = KJ * (KJ + 1) / 2;
  static constexpr int kSize = kHess + KJ + 1;  // upper-triangular Hessian, gradient, cost
};

// Row and column of slot s of the row-major upper triangle of an n x n matrix.
__device__ __forceinline__ void upper_index(int s, int n, int& row, int& col) {
  row = 0;
  while (s >= n - row) {
    s -= n - row;
    ++row;
  }
  col = row + s;
}

// __launch_bounds__: the float64 accumulators take up to ~250 registers (KJ = 8), which must fit one block.
template <int KJ>
__global__ void __launch_bounds__(kThreads)
    linearize_kernel(LinearizeConfig cfg, int hw, int height, int width, const float* __restrict__ rel,
                     const float* __restrict__ disps, const int64_t* __restrict__ ii,
                     const int64_t* __restrict__ jj, const float* __restrict__ target,
                     const float* __restrict__ weight, const float* __restrict__ umap,
                     double* __restrict__ partials, float* __restrict__ erows,
                     double* __restrict__ cdiag, double* __restrict__ wvec) {
  constexpr int kSize = Accum<KJ>::kSize;
  constexpr int kHess = Accum<KJ>::kHess;
  const int e = blockIdx.y;
  const int64_t fi = ii[e], fj = jj[e];
  const float* g = rel + static_cast<int64_t>(e) * kRelStride;
  const Pinhole k{cfg.fx, cfg.fy, cfg.cx, cfg.cy};

  double acc[kSize];
#pragma unroll
  for (int a = 0; a < kSize; ++a) acc[a] = 0.0;

  const int tile = static_cast<int>(blockIdx.x);
  const int tile_end = min(hw, (tile + 1) * kTilePixels);
  for (int p = tile * kTilePixels + static_cast<int>(threadIdx.x); p < tile_end; p += static_cast<int>(blockDim.x)) {
    const int u = p % width, v = p / width;
    const float d = disps[fi * hw + p];
    const Projected o = project_pixel(g, k, u, v, d, cfg.min_depth);
    const int64_t ep = static_cast<int64_t>(e) * hw + p;
    float scale = o.valid ? cfg.flow_weight_scale : 0.0f;
    if (umap != nullptr) {
      scale *= weight_factor(umap[fi * hw + p], cfg.uncertainty_mode);
      if (cfg.bidirectional)
        scale *= weight_factor(bilinear_sample(umap + fj * hw, bilinear_corners(o.px, o.py, height, width)),
                               cfg.uncertainty_mode);
    }
    const float wu = weight[2 * ep] * scale, wv = weight[2 * ep + 1] * scale;
    const float ru = target[2 * ep] - o.px, rv = target[2 * ep + 1] - o.py;

    // pose-j rows (twist [v, w]) then log-focal rows (droidw_pixel.h)
    float ju[KJ], jv[KJ];
    jacobian_rows<KJ>(o, g, k, cfg.focal_mode, d, ju, jv);

    // float64 sums of the float32 per-pixel terms
    const double dwu = wu, dwv = wv;
    int slot = 0;
#pragma unroll
    for (int a = 0; a < KJ; ++a) {
      const double au = dwu * ju[a], av = dwv * jv[a];
#pragma unroll
      for (int b = a; b < KJ; ++b) acc[slot++] += au * ju[b] + av * jv[b];
      acc[kHess + a] += au * ru + av * rv;
    }
    acc[kSize - 1] += dwu * ru * ru + dwv * rv * rv;

    if (cfg.with_depth) {
      float jdu, jdv;
      depth_derivative(o, g, k, jdu, jdv);
#pragma unroll
      for (int a = 0; a < KJ; ++a) erows[(static_cast<int64_t>(e) * KJ + a) * hw + p] = wu * ju[a] * jdu + wv * jv[a] * jdv;
      atomicAdd(cdiag + fi * hw + p, dwu * jdu * jdu + dwv * jdv * jdv);
      atomicAdd(wvec + fi * hw + p, dwu * jdu * ru + dwv * jdv * rv);
    }
  }

  // fixed-order block reduction: warp trees, then the warps in order; one partial per (edge, tile)
  __shared__ double partial[kThreads / kWarp][kSize];
  const int lane = threadIdx.x % kWarp, warp = threadIdx.x / kWarp;
#pragma unroll
  for (int a = 0; a < kSize; ++a) {
    const double s = warp_sum(acc[a]);
    if (lane == 0) partial[warp][a] = s;
  }
  __syncthreads();
  const int warps = blockDim.x / kWarp;
  double* out = partials + (static_cast<int64_t>(e) * gridDim.x + blockIdx.x) * kSize;
  for (int a = threadIdx.x; a < kSize; a += blockDim.x) {
    double s = 0.0;
    for (int w = 0; w < warps; ++w) s += partial[w][a];
    out[a] = s;
  }
}

// Sums the tiles of edge blockIdx.x in order and unpacks: hess_j (mirrored), grad_j, cost_e.
template <int KJ>
__global__ void finish_kernel(int tiles, const double* __restrict__ partials, double* __restrict__ hess_j,
                              double* __restrict__ grad_j, double* __restrict__ cost_e) {
  constexpr int kSize = Accum<KJ>::kSize;
  constexpr int kHess = Accum<KJ>::kHess;
  const int e = blockIdx.x;
  for (int a = threadIdx.x; a < kSize; a += blockDim.x) {
    const double* src = partials + static_cast<int64_t>(e) * tiles * kSize + a;
    double s = 0.0;
    for (int t = 0; t < tiles; ++t) s += src[static_cast<int64_t>(t) * kSize];
    if (a < kHess) {
      int row, col;
      upper_index(a, KJ, row, col);
      double* h = hess_j + static_cast<int64_t>(e) * KJ * KJ;
      h[row * KJ + col] = s;
      h[col * KJ + row] = s;
    } else if (a < kSize - 1) {
      grad_j[static_cast<int64_t>(e) * KJ + (a - kHess)] = s;
    } else {
      cost_e[e] = s;
    }
  }
}

struct Outputs {
  torch::Tensor hess_j, grad_j, cost_e, erows, cdiag, wvec;  // cdiag, wvec float64 here
};

template <int KJ>
void launch(const LinearizeConfig& cfg, const LinearizeInputs& in, int height, int width, Outputs& out) {
  const int hw = height * width;
  const int64_t edges = in.ii.size(0);
  const int tiles = (hw + kTilePixels - 1) / kTilePixels;
  const torch::Tensor partials = torch::empty({edges, tiles, Accum<KJ>::kSize}, in.disps.options().dtype(at::kDouble));
  auto stream = c10::cuda::getCurrentCUDAStream();
  const dim3 grid(tiles, static_cast<unsigned>(edges));
  linearize_kernel<KJ><<<grid, kThreads, 0, stream>>>(
      cfg, hw, height, width, in.rel.data_ptr<float>(), in.disps.data_ptr<float>(), in.ii.data_ptr<int64_t>(),
      in.jj.data_ptr<int64_t>(), in.target.data_ptr<float>(), in.weight.data_ptr<float>(),
      in.umap.defined() ? in.umap.data_ptr<float>() : nullptr, partials.data_ptr<double>(),
      cfg.with_depth ? out.erows.data_ptr<float>() : nullptr, cfg.with_depth ? out.cdiag.data_ptr<double>() : nullptr,
      cfg.with_depth ? out.wvec.data_ptr<double>() : nullptr);
  C10_CUDA_KERNEL_LAUNCH_CHECK();
  finish_kernel<KJ><<<static_cast<unsigned>(edges), kFinishThreads, 0, stream>>>(
      tiles, partials.data_ptr<double>(), out.hess_j.data_ptr<double>(), out.grad_j.data_ptr<double>(),
      out.cost_e.data_ptr<double>());
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
  const int64_t hw = static_cast<int64_t>(height) * width;
  const int64_t edges = in.ii.size(0);
  const int nf = cfg.focal_mode == kFocalShared ? 1 : (cfg.focal_mode == kFocalXY ? 2 : 0);
  const int kj = kPoseDof + nf;
  auto f64 = in.disps.options().dtype(at::kDouble);
  Outputs out;
  out.hess_j = torch::zeros({edges, kj, kj}, f64);
  out.grad_j = torch::zeros({edges, kj}, f64);
  out.cost_e = torch::zeros({edges}, f64);
  if (cfg.with_depth) {
    out.erows = torch::empty({edges, kj, hw}, in.disps.options());
    out.cdiag = torch::zeros({n, hw}, f64);
    out.wvec = torch::zeros({n, hw}, f64);
  }
  if (edges > 0) {
    if (nf == 0) launch<kPoseDof>(cfg, in, height, width, out);
    else if (nf == 1) launch<kPoseDof + 1>(cfg, in, height, width, out);
    else launch<kPoseDof + kMaxFocalDof>(cfg, in, height, width, out);
  }
  torch::Tensor cdiag, wvec;
  if (cfg.with_depth) {
    cdiag = out.cdiag.to(at::kFloat);
    wvec = out.wvec.to(at::kFloat);
  }
  auto cost = out.cost_e.sum().reshape({1});  // a fixed-order reduction over the edges
  return {out.hess_j, out.grad_j, out.erows, cdiag, wvec, cost};
}

}  // namespace droidw

// The per-pixel maths of droidw's uncertainty-aware BA (DROID-W Eq. 1-9), shared by the compiled backends:
// the native CPU backend (backends/native, g++) and the CUDA kernels (backends/cuda, nvcc) include this
// header, so a CPU-only test run exercises the very functions the CUDA kernels call.  Plain C++ with
// DROIDW_HD = `__host__ __device__ __forceinline__` under nvcc and `inline` elsewhere; no torch here (C++17).
//
// Conventions (droidw_cli.ba.types, droidw_cli.geometry.projection):
//   g      12 floats of G_ij = G_j G_i^-1: R row-major (9), then t (3)
//   pixel  (u, v) of the H x W grid sits at x = u, y = v; flat index p = v W + u
//   Eq. 1  (X, Y, Z) = R (x_bar, y_bar, 1) + t d,  z = 1/Z,  (x^, y^) = (X z, Y z),  p_ij = (fx x^ + cx, fy y^ + cy)
//          valid = d > 0 and 1/d >= m and Z/d >= m   (m = min_depth)
#pragma once

#include <math.h>
#include <stdint.h>

#if defined(__CUDACC__)
#define DROIDW_HD __host__ __device__ __forceinline__
#else
#define DROIDW_HD inline
#endif

namespace droidw {

// Constants of the DROID-W clamp weighting: clamp(1 / max(SLOPE u - OFFSET, FLOOR), 0, 1).
constexpr float kClampSlope = 45.0f;
constexpr float kClampOffset = 35.0f;
constexpr float kClampFloor = 0.1f;
// Guards the cosine similarity against zero-norm features (droidw_cli.ba.uncertainty.COS_EPS).
constexpr float kCosEps = 1e-8f;
constexpr int kPoseDof = 6;
constexpr int kMaxFocalDof = 2;
constexpr int kRelStride = 12;  // R (9) + t (3) per edge

enum UncertaintyMode : int { kUncertaintyOff = 0, kUncertaintyClamp = 1, kUncertaintyInverse = 2 };
enum FocalMode : int { kFocalNone = 0, kFocalShared = 1, kFocalXY = 2 };

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

DROIDW_HD Projected project_pixel(const float* g, const Pinhole& k, int u, int v, float d, float min_depth) {
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

// Border-clamped bilinear corners (x0,y0), (x0+1,y0), (x0,y0+1), (x0+1,y0+1) as flat indices, x0 = min(floor x, W-2)
// (droidw_cli.geometry.sampling.bilinear_corners).
struct Bilinear {
  int idx[4];
  float w[4];
};

DROIDW_HD Bilinear bilinear_corners(float x, float y, int h, int w) {
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

// Sum_c w_c map[q_c]: a scalar map (H W,) sampled at the corners b.
DROIDW_HD float bilinear_sample(const float* map, const Bilinear& b) {
  return b.w[0] * map[b.idx[0]] + b.w[1] * map[b.idx[1]] + b.w[2] * map[b.idx[2]] + b.w[3] * map[b.idx[3]];
}

DROIDW_HD bool inside_image(float x, float y, int h, int w) {
  return x >= 0.0f && x <= static_cast<float>(w - 1) && y >= 0.0f && y <= static_cast<float>(h - 1);
}

// The BA confidence multiplier f(u) of Eq. 5 (droidw_cli.ba.uncertainty.weight_factor).
DROIDW_HD float weight_factor(float u, int mode) {
  if (mode == kUncertaintyClamp) {
    const float f = 1.0f / fmaxf(kClampSlope * u - kClampOffset, kClampFloor);
    return fminf(fmaxf(f, 0.0f), 1.0f);
  }
  if (mode == kUncertaintyInverse) return 1.0f / u;
  return 1.0f;
}

// Rows of dp/dxi_j (twist [v, w]) and of dp/dlog-focal for the u and v components (KJ = 6 + nf):
//   J_u = fx [d z, 0, -x^ d z, -x^y^, 1 + x^2, -y^],   J_v = fy [0, d z, -y^ d z, -(1 + y^2), x^y^, x^]
//   dp/dfx = (x^ - x_bar z (R00 - x^ R20), -(fy/fx) x_bar z (R10 - y^ R20))
//   dp/dfy = (-(fx/fy) y_bar z (R01 - x^ R21), y^ - y_bar z (R11 - y^ R21))
// the log-focal rows are fx dp/dfx, fy dp/dfy ("xy") or their sum ("shared").
template <int KJ>
DROIDW_HD void jacobian_rows(const Projected& o, const float* g, const Pinhole& k, int focal_mode, float d,
                             float* ju, float* jv) {
  const float dz = d * o.z, xy = o.x * o.y;
  ju[0] = k.fx * dz;                    jv[0] = 0.0f;
  ju[1] = 0.0f;                         jv[1] = k.fy * dz;
  ju[2] = -k.fx * o.x * dz;             jv[2] = -k.fy * o.y * dz;
  ju[3] = -k.fx * xy;                   jv[3] = -k.fy * (1.0f + o.y * o.y);
  ju[4] = k.fx * (1.0f + o.x * o.x);    jv[4] = k.fy * xy;
  ju[5] = -k.fx * o.y;                  jv[5] = k.fy * o.x;
  if constexpr (KJ > kPoseDof) {
    const float dfx_u = o.x - o.xbar * o.z * (g[0] - o.x * g[6]);
    const float dfx_v = -(k.fy / k.fx) * o.xbar * o.z * (g[3] - o.y * g[6]);
    const float dfy_u = -(k.fx / k.fy) * o.ybar * o.z * (g[1] - o.x * g[7]);
    const float dfy_v = o.y - o.ybar * o.z * (g[4] - o.y * g[7]);
    if (focal_mode == kFocalShared) {
      ju[kPoseDof] = k.fx * dfx_u + k.fy * dfy_u;
      jv[kPoseDof] = k.fx * dfx_v + k.fy * dfy_v;
    } else {
      ju[kPoseDof] = k.fx * dfx_u;
      jv[kPoseDof] = k.fx * dfx_v;
      if constexpr (KJ > kPoseDof + 1) {
        ju[KJ - 1] = k.fy * dfy_u;
        jv[KJ - 1] = k.fy * dfy_v;
      }
    }
  }
}

// dp/dd = (fx z (t_x - x^ t_z), fy z (t_y - y^ t_z)).
DROIDW_HD void depth_derivative(const Projected& o, const float* g, const Pinhole& k, float& jdu, float& jdv) {
  jdu = k.fx * o.z * (g[9] - o.x * g[11]);
  jdv = k.fy * o.z * (g[10] - o.y * g[11]);
}

// s = clamp(cos, 0, 1) exp(-(r / sigma_g)^2) (the factor only when sigma_g > 0 and r >= 0 is given), 0 below the
// threshold (droidw_cli.ba.uncertainty.similarity_score).
DROIDW_HD float similarity_score(float cosv, float threshold, float residual, float geo_sigma) {
  float s = fminf(fmaxf(cosv, 0.0f), 1.0f);
  if (geo_sigma > 0.0f && residual >= 0.0f) {
    const float r = residual / geo_sigma;
    s *= expf(-r * r);
  }
  return s < threshold ? 0.0f : s;
}

// t = omega gamma_data valid (1 - s) / (u_i u_ij): the E_sim term of one pixel (Eq. 7); its gradient is
// dE/du_i = -t / u_i and dE/du_ij = -t / u_ij.
DROIDW_HD float similarity_term(float sim, bool valid, float gamma_omega, float ui, float uij) {
  return valid ? gamma_omega * (1.0f - sim) / (ui * uij) : 0.0f;
}

}  // namespace droidw

// Projection of 3-D Gaussians to 2-D (EWA splatting, gsplat's asymmetric clamp) and its VJP; tile binning.
// Semantics: docs/rasterizer.md.  No torch headers here: ops.cpp wraps these functions.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <numeric>
#include <type_traits>
#include <vector>

#include "kernels.h"
#include "pair_math.h"
#include "tile_geom.h"

namespace eigs {
namespace {

constexpr double kNear = 0.01;        // cull camera-space z < kNear
constexpr double kBlur = 0.3;         // low-pass added to the 2-D covariance diagonal (px^2)
constexpr double kClampFov = 0.3;     // J is evaluated at x/z clamped to the image extent + 0.3 tan(fov/2)
constexpr double kMinQuatNorm2 = 1e-12;
constexpr double kMinScale = 1e-8;
constexpr double kExtentRel = 1e-3;   // relative and absolute margins that keep the box conservative under
constexpr double kExtentAbs = 1e-3;   // rounding of the conic and of alpha (px)

template <typename S>
inline bool finite(S v) {
    return std::isfinite(v);
}

// Everything the forward computes for one Gaussian; the backward recomputes it.
template <typename S>
struct Proj {
    S q[4];        // normalised quaternion (w, x, y, z)
    S inv_norm;    // 1 / |q|
    S Rq[9];       // rotation of the Gaussian
    S M[9];        // Rq diag(scale)
    S Ccam[9];     // camera-space 3-D covariance
    S t[3];        // camera-space mean
    S ux, uy;      // x/z, y/z (unclamped)
    S cux, cuy;    // clamped
    bool mx, my;   // clamp passes the gradient (inside the limits, inclusive)
    S J[6];        // 2x3 Jacobian, row-major
    S cov2[3];     // 2-D covariance (xx, xy, yy) including the blur
    S det;
    S conic[3];
    S mean2d[2];
};

template <typename S>
inline void mat3_mul(const S* A, const S* B, S* C) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) C[i * 3 + j] = A[i * 3] * B[j] + A[i * 3 + 1] * B[3 + j] + A[i * 3 + 2] * B[6 + j];
}

template <typename S>
inline void mat3_mul_bt(const S* A, const S* B, S* C) {  // A B^T
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            C[i * 3 + j] = A[i * 3] * B[j * 3] + A[i * 3 + 1] * B[j * 3 + 1] + A[i * 3 + 2] * B[j * 3 + 2];
}

template <typename S>
inline void mat3_mul_at(const S* A, const S* B, S* C) {  // A^T B
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) C[i * 3 + j] = A[i] * B[j] + A[3 + i] * B[3 + j] + A[6 + i] * B[6 + j];
}

// Returns false when the Gaussian is culled.  Fills p for a kept Gaussian.
template <typename S>
bool project_one(const S* mean, const S* quat, const S* scale, S opacity, const Camera<S>& cam, Proj<S>& p) {
    for (int k = 0; k < 3; ++k)
        if (!finite(mean[k]) || !finite(scale[k])) return false;
    for (int k = 0; k < 4; ++k)
        if (!finite(quat[k])) return false;
    if (!finite(opacity) || !(opacity >= S(kAlphaMin))) return false;
    for (int k = 0; k < 3; ++k)
        if (!(scale[k] > S(kMinScale))) return false;
    const S n2 = quat[0] * quat[0] + quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3];
    if (!(n2 >= S(kMinQuatNorm2))) return false;

    for (int i = 0; i < 3; ++i)
        p.t[i] = cam.R[i * 3] * mean[0] + cam.R[i * 3 + 1] * mean[1] + cam.R[i * 3 + 2] * mean[2] + cam.t[i];
    const S z = p.t[2];
    if (!(z >= S(kNear)) || !finite(p.t[0]) || !finite(p.t[1]) || !finite(z)) return false;

    p.inv_norm = S(1) / std::sqrt(n2);
    for (int k = 0; k < 4; ++k) p.q[k] = quat[k] * p.inv_norm;
    const S w = p.q[0], x = p.q[1], y = p.q[2], zq = p.q[3];
    S* R = p.Rq;
    R[0] = S(1) - S(2) * (y * y + zq * zq);
    R[1] = S(2) * (x * y - w * zq);
    R[2] = S(2) * (x * zq + w * y);
    R[3] = S(2) * (x * y + w * zq);
    R[4] = S(1) - S(2) * (x * x + zq * zq);
    R[5] = S(2) * (y * zq - w * x);
    R[6] = S(2) * (x * zq - w * y);
    R[7] = S(2) * (y * zq + w * x);
    R[8] = S(1) - S(2) * (x * x + y * y);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) p.M[i * 3 + j] = R[i * 3 + j] * scale[j];
    S Sig[9], RS[9];
    mat3_mul_bt(p.M, p.M, Sig);      // Sigma = M M^T
    mat3_mul(cam.R, Sig, RS);        // R_w Sigma
    mat3_mul_bt(RS, cam.R, p.Ccam);  // R_w Sigma R_w^T

    const S W = S(cam.width), H = S(cam.height);
    const S lim_xp = (W - cam.cx) / cam.fx + S(kClampFov) * W / (S(2) * cam.fx);
    const S lim_xn = cam.cx / cam.fx + S(kClampFov) * W / (S(2) * cam.fx);
    const S lim_yp = (H - cam.cy) / cam.fy + S(kClampFov) * H / (S(2) * cam.fy);
    const S lim_yn = cam.cy / cam.fy + S(kClampFov) * H / (S(2) * cam.fy);
    p.ux = p.t[0] / z;
    p.uy = p.t[1] / z;
    p.mx = (p.ux >= -lim_xn) && (p.ux <= lim_xp);
    p.my = (p.uy >= -lim_yn) && (p.uy <= lim_yp);
    p.cux = std::min(std::max(p.ux, -lim_xn), lim_xp);
    p.cuy = std::min(std::max(p.uy, -lim_yn), lim_yp);
    const S txc = z * p.cux, tyc = z * p.cuy;
    const S iz = S(1) / z;
    p.J[0] = cam.fx * iz;
    p.J[1] = S(0);
    p.J[2] = -cam.fx * txc * iz * iz;
    p.J[3] = S(0);
    p.J[4] = cam.fy * iz;
    p.J[5] = -cam.fy * tyc * iz * iz;
    // cov2 = J C J^T (2x2): row r of J times C times row s of J.
    S JC[6];
    for (int r = 0; r < 2; ++r)
        for (int j = 0; j < 3; ++j)
            JC[r * 3 + j] = p.J[r * 3] * p.Ccam[j] + p.J[r * 3 + 1] * p.Ccam[3 + j] + p.J[r * 3 + 2] * p.Ccam[6 + j];
    const S s00 = JC[0] * p.J[0] + JC[1] * p.J[1] + JC[2] * p.J[2] + S(kBlur);
    const S s01 = JC[0] * p.J[3] + JC[1] * p.J[4] + JC[2] * p.J[5];
    const S s11 = JC[3] * p.J[3] + JC[4] * p.J[4] + JC[5] * p.J[5] + S(kBlur);
    p.cov2[0] = s00;
    p.cov2[1] = s01;
    p.cov2[2] = s11;
    // det by Cauchy-Binet on T = J R_w M (2x3, cov2 = T T^T + blur I): the 2x2 minors of T squared, plus
    // blur * trace + blur^2. The direct s00 s11 - s01^2 cancels catastrophically in float32 for needles (a long
    // axis of L px leaves an absolute error ~ L^4 * 6e-8 against a determinant ~ 0.3 L^2).
    S RM[9], T[6];
    mat3_mul(cam.R, p.M, RM);
    for (int r = 0; r < 2; ++r)
        for (int j = 0; j < 3; ++j)
            T[r * 3 + j] = p.J[r * 3] * RM[j] + p.J[r * 3 + 1] * RM[3 + j] + p.J[r * 3 + 2] * RM[6 + j];
    const S m01 = T[0] * T[4] - T[1] * T[3], m02 = T[0] * T[5] - T[2] * T[3], m12 = T[1] * T[5] - T[2] * T[4];
    const S tr = T[0] * T[0] + T[1] * T[1] + T[2] * T[2] + T[3] * T[3] + T[4] * T[4] + T[5] * T[5];
    p.det = (m01 * m01 + m02 * m02 + m12 * m12) + S(kBlur) * tr + S(kBlur) * S(kBlur);
    if (!(p.det > S(0)) || !finite(p.det)) return false;
    const S idet = S(1) / p.det;
    p.conic[0] = s11 * idet;
    p.conic[1] = -s01 * idet;
    p.conic[2] = s00 * idet;
    p.mean2d[0] = cam.fx * p.ux + cam.cx;
    p.mean2d[1] = cam.fy * p.uy + cam.cy;
    for (int k = 0; k < 3; ++k)
        if (!finite(p.conic[k])) return false;
    if (!finite(p.mean2d[0]) || !finite(p.mean2d[1])) return false;
    return true;
}

}  // namespace

template <typename S>
void project_forward(int64_t n, const S* means, const S* quats, const S* scales, const S* opacities,
                     const S* colors, int64_t d, const Camera<S>& cam, S* means2d, S* conics, S* depths,
                     S* extents, int32_t* radii, int nthreads) {
#pragma omp parallel for num_threads(nthreads) schedule(static)
    for (int64_t g = 0; g < n; ++g) {
        Proj<S> p;
        bool keep = true;
        for (int64_t ch = 0; ch < d; ++ch) keep &= finite(colors[g * d + ch]);  // a non-finite colour culls
        keep = keep && project_one(means + 3 * g, quats + 4 * g, scales + 3 * g, opacities[g], cam, p);
        double ex = 0, ey = 0;
        if (keep) {
            // Opacity-aware box: o exp(-sigma) >= 1/255  <=>  sigma <= L = ln(255 o), and on the ellipse
            // sigma <= L the largest |dx| is sqrt(2 L cov_xx).  Margins absorb rounding.
            const double L = std::max(0.0, std::log(double(opacities[g]) / kAlphaMin));
            const double e = std::sqrt(2.0 * L);
            ex = e * std::sqrt(double(p.cov2[0])) * (1.0 + kExtentRel) + kExtentAbs;
            ey = e * std::sqrt(double(p.cov2[2])) * (1.0 + kExtentRel) + kExtentAbs;
            int64_t j0, j1, i0, i1;
            pixel_range(double(p.mean2d[0]), ex, cam.width, j0, j1);
            pixel_range(double(p.mean2d[1]), ey, cam.height, i0, i1);
            if (j0 > j1 || i0 > i1 || !std::isfinite(ex) || !std::isfinite(ey)) keep = false;
        }
        if (keep) {
            means2d[2 * g] = p.mean2d[0];
            means2d[2 * g + 1] = p.mean2d[1];
            for (int k = 0; k < 3; ++k) conics[3 * g + k] = p.conic[k];
            depths[g] = p.t[2];
            extents[2 * g] = S(ex);
            extents[2 * g + 1] = S(ey);
            const double imax = double(std::numeric_limits<int32_t>::max());
            radii[2 * g] = int32_t(std::min(std::ceil(ex), imax));
            radii[2 * g + 1] = int32_t(std::min(std::ceil(ey), imax));
        } else {
            means2d[2 * g] = means2d[2 * g + 1] = S(0);
            conics[3 * g] = conics[3 * g + 1] = conics[3 * g + 2] = S(0);
            depths[g] = S(0);
            extents[2 * g] = extents[2 * g + 1] = S(0);
            radii[2 * g] = radii[2 * g + 1] = 0;
        }
    }
}

template <typename S>
void project_backward(int64_t n, const S* means, const S* quats, const S* scales, const Camera<S>& cam,
                      const int32_t* radii, const S* v_means2d, const S* v_conics, S* v_means, S* v_quats,
                      S* v_scales, int nthreads) {
#pragma omp parallel for num_threads(nthreads) schedule(static)
    for (int64_t g = 0; g < n; ++g) {
        for (int k = 0; k < 3; ++k) v_means[3 * g + k] = v_scales[3 * g + k] = S(0);
        for (int k = 0; k < 4; ++k) v_quats[4 * g + k] = S(0);
        if (radii[2 * g] <= 0) continue;
        Proj<S> p;
        // The opacity test was passed in the forward; use 1 so that only the geometric culls apply.
        if (!project_one(means + 3 * g, quats + 4 * g, scales + 3 * g, S(1), cam, p)) continue;
        const S* scale = scales + 3 * g;
        const S z = p.t[2], iz = S(1) / z, iz2 = iz * iz;

        // conic = inverse(cov2): with P the conic matrix and G the full-matrix gradient
        // (G01 = G10 = v_b / 2), v_cov2 = -P G P.
        const S a = p.conic[0], b = p.conic[1], c = p.conic[2];
        const S ga = v_conics[3 * g], gb = S(0.5) * v_conics[3 * g + 1], gc = v_conics[3 * g + 2];
        // PG = P G
        const S pg00 = a * ga + b * gb, pg01 = a * gb + b * gc;
        const S pg10 = b * ga + c * gb, pg11 = b * gb + c * gc;
        S V[4];  // v_cov2 (full 2x2, symmetric)
        V[0] = -(pg00 * a + pg01 * b);
        V[1] = -(pg00 * b + pg01 * c);
        V[2] = -(pg10 * a + pg11 * b);
        V[3] = -(pg10 * b + pg11 * c);

        // cov2 = J C J^T + blur:  v_C = J^T V J,  v_J = V J C^T + V^T J C.
        S VJ[6];  // V J (2x3)
        for (int r = 0; r < 2; ++r)
            for (int j = 0; j < 3; ++j) VJ[r * 3 + j] = V[r * 2] * p.J[j] + V[r * 2 + 1] * p.J[3 + j];
        S vC[9];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) vC[i * 3 + j] = p.J[i] * VJ[j] + p.J[3 + i] * VJ[3 + j];
        S VtJ[6];  // V^T J
        for (int r = 0; r < 2; ++r)
            for (int j = 0; j < 3; ++j) VtJ[r * 3 + j] = V[r] * p.J[j] + V[2 + r] * p.J[3 + j];
        S vJ[6];
        for (int r = 0; r < 2; ++r)
            for (int j = 0; j < 3; ++j) {
                S acc = S(0);
                for (int k = 0; k < 3; ++k)
                    acc += VJ[r * 3 + k] * p.Ccam[j * 3 + k] + VtJ[r * 3 + k] * p.Ccam[k * 3 + j];
                vJ[r * 3 + j] = acc;
            }

        // J = [[fx/z, 0, -fx txc/z^2], [0, fy/z, -fy tyc/z^2]], txc = z clamp(x/z).
        S vt[3] = {S(0), S(0), S(0)};
        const S txc = z * p.cux, tyc = z * p.cuy;
        vt[2] += -cam.fx * iz2 * vJ[0] - cam.fy * iz2 * vJ[4];
        vt[2] += S(2) * cam.fx * txc * iz2 * iz * vJ[2] + S(2) * cam.fy * tyc * iz2 * iz * vJ[5];
        const S v_txc = -cam.fx * iz2 * vJ[2], v_tyc = -cam.fy * iz2 * vJ[5];
        // d txc / dx = m, d txc / dz = clamp(u) - m u   (m: the clamp passes the gradient)
        vt[0] += p.mx ? v_txc : S(0);
        vt[1] += p.my ? v_tyc : S(0);
        vt[2] += v_txc * (p.cux - (p.mx ? p.ux : S(0))) + v_tyc * (p.cuy - (p.my ? p.uy : S(0)));
        // mean2d = (fx x/z + cx, fy y/z + cy)
        const S gmx = v_means2d[2 * g], gmy = v_means2d[2 * g + 1];
        vt[0] += cam.fx * iz * gmx;
        vt[1] += cam.fy * iz * gmy;
        vt[2] += -(cam.fx * p.t[0] * gmx + cam.fy * p.t[1] * gmy) * iz2;
        // t = R_w mean + t_w
        for (int k = 0; k < 3; ++k)
            v_means[3 * g + k] = cam.R[k] * vt[0] + cam.R[3 + k] * vt[1] + cam.R[6 + k] * vt[2];

        // C = R_w Sigma R_w^T: v_Sigma = R_w^T v_C R_w
        S tmp[9], vSig[9];
        mat3_mul_at(cam.R, vC, tmp);
        mat3_mul(tmp, cam.R, vSig);
        // Sigma = M M^T: v_M = (v_Sigma + v_Sigma^T) M
        S vSym[9];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) vSym[i * 3 + j] = vSig[i * 3 + j] + vSig[j * 3 + i];
        S vM[9];
        mat3_mul(vSym, p.M, vM);
        // M = Rq diag(s)
        S vR[9];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) vR[i * 3 + j] = vM[i * 3 + j] * scale[j];
        for (int j = 0; j < 3; ++j)
            v_scales[3 * g + j] = vM[j] * p.Rq[j] + vM[3 + j] * p.Rq[3 + j] + vM[6 + j] * p.Rq[6 + j];
        // Rq(q_hat) -> v_q_hat
        const S w = p.q[0], x = p.q[1], y = p.q[2], zq = p.q[3];
        S vq[4];
        vq[0] = S(2) * (-zq * vR[1] + y * vR[2] + zq * vR[3] - x * vR[5] - y * vR[6] + x * vR[7]);
        vq[1] = S(2) * (y * vR[1] + zq * vR[2] + y * vR[3] - S(2) * x * vR[4] - w * vR[5] + zq * vR[6] +
                        w * vR[7] - S(2) * x * vR[8]);
        vq[2] = S(2) * (-S(2) * y * vR[0] + x * vR[1] + w * vR[2] + x * vR[3] + zq * vR[5] - w * vR[6] +
                        zq * vR[7] - S(2) * y * vR[8]);
        vq[3] = S(2) * (-S(2) * zq * vR[0] - w * vR[1] + x * vR[2] + w * vR[3] - S(2) * zq * vR[4] +
                        y * vR[5] + x * vR[6] + y * vR[7]);
        // q_hat = q / |q|: v_q = (v_q_hat - q_hat (q_hat . v_q_hat)) / |q|
        const S dot = w * vq[0] + x * vq[1] + y * vq[2] + zq * vq[3];
        for (int k = 0; k < 4; ++k) v_quats[4 * g + k] = (vq[k] - p.q[k] * dot) * p.inv_norm;
    }
}

namespace {

// Sort key of a visible Gaussian: ascending depth, ties by index (keys are unique, so any correct sort or merge
// gives the same order).
template <typename S>
struct DepthKey {
    S depth;
    int64_t g;
    bool operator<(const DepthKey& o) const { return depth < o.depth || (depth == o.depth && g < o.g); }
};

// Sorts keys[0, m) by (depth, index), given that they arrive in ascending index: a stable LSD radix sort on the
// depth's bit pattern (depths are positive, so their IEEE bit patterns order like the values), 8-bit digits,
// skipping digits that all keys share, with tmp[0, m) as scratch.  Same order as std::sort on the unique keys,
// ~2-3x faster at 1k-100k keys; short runs use std::sort.
template <typename S>
void sort_by_depth(DepthKey<S>* keys, DepthKey<S>* tmp, int64_t m) {
    if (m < 256) {
        std::sort(keys, keys + m);
        return;
    }
    using U = std::conditional_t<sizeof(S) == 4, uint32_t, uint64_t>;
    const auto bits = [](S d) {
        U u;
        std::memcpy(&u, &d, sizeof u);
        return u;
    };
    DepthKey<S>* src = keys;
    DepthKey<S>* dst = tmp;
    for (int shift = 0; shift < int(8 * sizeof(S)); shift += 8) {
        int64_t count[256] = {};
        for (int64_t i = 0; i < m; ++i) ++count[(bits(src[i].depth) >> shift) & 255];
        if (count[(bits(src[0].depth) >> shift) & 255] == m) continue;  // every key has this digit
        int64_t pos = 0;
        for (int64_t& c : count) {
            const int64_t v = c;
            c = pos;
            pos += v;
        }
        for (int64_t i = 0; i < m; ++i) dst[count[(bits(src[i].depth) >> shift) & 255]++] = src[i];
        std::swap(src, dst);
    }
    if (src != keys) std::copy(src, src + m, keys);
}

// [lo, hi) of chunk c of n items split into k near-equal chunks.
inline int64_t chunk_lo(int64_t n, int k, int c) { return n * c / k; }

// Co-rank of output position p in the merge of sorted runs a (na) and b (nb) of unique keys: the number of
// elements of a among the first p outputs.  Lets several threads merge disjoint output ranges of one merge.
template <typename K>
int64_t co_rank(int64_t p, const K* a, int64_t na, const K* b, int64_t nb) {
    int64_t lo = std::max<int64_t>(0, p - nb), hi = std::min(p, na);
    while (lo < hi) {
        const int64_t i = lo + (hi - lo) / 2, j = p - i;
        if (j > 0 && i < na && a[i] < b[j - 1])
            lo = i + 1;
        else
            hi = i;
    }
    return lo;
}

}  // namespace

// Calls f(tile) for every tile Gaussian g is binned to, in row-major tile order: the tiles of its rectangle and,
// when the plan culls, only those that tile_mask or tile_row_span keep (tile_geom.h).
template <typename F>
inline void for_each_tile(const IsectPlan& plan, int64_t g, F&& f) {
    const int32_t* r = plan.rect.get() + 4 * g;
    const TileCull kind = plan.masks ? tile_cull_kind(r) : TileCull::kNone;
    if (kind == TileCull::kMask && plan.masks[g] != kAllTiles) {
        const int64_t nx = r[1] - r[0] + 1;
        for (uint64_t bits = plan.masks[g]; bits != 0; bits &= bits - 1) {
            const int64_t k = __builtin_ctzll(bits);
            f((r[2] + k / nx) * plan.tiles_x + r[0] + k % nx);
        }
        return;
    }
    for (int64_t ty = r[2]; ty <= r[3]; ++ty) {
        int32_t c0 = r[0], c1 = r[1];
        if (kind == TileCull::kRows && !tile_row_span(plan.ellipses[g], r, ty, c0, c1)) continue;
        for (int64_t tx = c0; tx <= c1; ++tx) f(ty * plan.tiles_x + tx);
    }
}

template <typename S>
int64_t isect_plan(const BinInputs<S>& b, const S* depths, const int32_t* radii, int64_t* tile_offsets,
                   IsectPlan& plan, int nthreads) {
    const int64_t n = b.n, width = b.width, height = b.height;
    const S *means2d = b.means2d, *extents = b.extents;
    using Key = DepthKey<S>;
    const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
    const int64_t n_tiles = tiles_x * tiles_y;
    const int k = std::max(1, nthreads);
    const size_t n1 = size_t(std::max<int64_t>(n, 1));
    plan.n_tiles = n_tiles;
    plan.tiles_x = tiles_x;
    plan.nchunks = k;
    plan.rect.reset(new int32_t[4 * n1]);
    if (b.conics != nullptr) {  // tile culling: a mask per Gaussian, the ellipse's rows for the large rectangles
        plan.masks.reset(new uint64_t[n1]);
        plan.ellipses.reset(new EllipseRows[n1]);
    }
    uint64_t* masks = plan.masks.get();
    EllipseRows* ellipses = plan.ellipses.get();
    plan.order.reset(new int64_t[n1]);
    std::vector<int64_t> kept(size_t(k) + 1, 0);
    std::unique_ptr<Key[]> keys_buf(new Key[n1]), tmp_buf(new Key[n1]);
    Key* keys = keys_buf.get();
    Key* tmp = tmp_buf.get();
    plan.cursor.assign(size_t(k) * size_t(n_tiles), 0);
    int32_t* rect = plan.rect.get();
    int64_t* order = plan.order.get();
    int64_t* cnt = plan.cursor.data();
    std::vector<int64_t> starts;  // run boundaries, rewritten by one thread between merge rounds
#pragma omp parallel num_threads(k)
    {
        // 1. per chunk of Gaussians: tile rectangles of the visible ones, compacted into keys, sorted.
#pragma omp for schedule(static, 1)
        for (int c = 0; c < k; ++c) {
            const int64_t lo = chunk_lo(n, k, c), hi = chunk_lo(n, k, c + 1);
            int64_t m = 0;
            for (int64_t g = lo; g < hi; ++g) {
                int32_t* r = rect + 4 * g;
                r[0] = r[2] = 1;
                r[1] = r[3] = 0;
                if (radii[2 * g] <= 0 || !tile_rect(means2d + 2 * g, extents + 2 * g, width, height, r)) continue;
                const TileCull kind = masks ? tile_cull_kind(r) : TileCull::kNone;
                if (kind != TileCull::kNone) {
                    const EllipseRows e = ellipse_rows(means2d + 2 * g, extents + 2 * g, b.conics + 3 * g,
                                                       b.opacities[g], width, height);
                    if (kind == TileCull::kMask)
                        masks[g] = tile_mask(e, r);
                    else
                        ellipses[g] = e;
                }
                keys[lo + m] = Key{depths[g], g};
                ++m;
            }
            kept[size_t(c) + 1] = m;
            sort_by_depth(keys + lo, tmp + lo, m);
        }
        // 2. compact the sorted runs (serial, in place: each run moves left), then pairwise merge rounds; every
        // merge's output is cut into k pieces at co-ranks and the pieces are merged by all threads.
#pragma omp single
        {
            int64_t pos = 0;
            for (int c = 0; c < k; ++c) {
                const int64_t lo = chunk_lo(n, k, c), m = kept[size_t(c) + 1];
                if (lo != pos) std::move(keys + lo, keys + lo + m, keys + pos);
                starts.push_back(pos);
                pos += m;
            }
            starts.push_back(pos);
            kept[0] = pos;
        }
        while (starts.size() > 2) {
            const int64_t runs = int64_t(starts.size()) - 1;
#pragma omp for schedule(static, 1) collapse(2)
            for (int64_t r = 0; r < runs; r += 2) {
                for (int piece = 0; piece < k; ++piece) {
                    const int64_t a = starts[size_t(r)], b = starts[size_t(r) + 1];
                    const int64_t e = r + 2 <= runs ? starts[size_t(r) + 2] : b;
                    const int64_t na = b - a, nb = e - b;
                    const int64_t p0 = (na + nb) * piece / k, p1 = (na + nb) * (piece + 1) / k;
                    const int64_t i0 = co_rank(p0, keys + a, na, keys + b, nb);
                    const int64_t i1 = co_rank(p1, keys + a, na, keys + b, nb);
                    std::merge(keys + a + i0, keys + a + i1, keys + b + (p0 - i0), keys + b + (p1 - i1),
                               tmp + a + p0);
                }
            }
#pragma omp single
            {
                std::vector<int64_t> next;
                for (int64_t r = 0; r < runs; r += 2) next.push_back(starts[size_t(r)]);
                next.push_back(starts.back());
                starts.swap(next);
                std::swap(keys, tmp);
            }
        }
        const int64_t m = kept[0];
        // 3. per chunk of the sorted order: the order itself and its pair count per tile.
#pragma omp for schedule(static, 1)
        for (int c = 0; c < k; ++c) {
            int64_t* cc = cnt + size_t(c) * size_t(n_tiles);
            for (int64_t i = chunk_lo(m, k, c); i < chunk_lo(m, k, c + 1); ++i) {
                const int64_t g = keys[i].g;
                order[i] = g;
                for_each_tile(plan, g, [cc](int64_t t) { ++cc[t]; });
            }
        }
    }
    plan.n_visible = kept[0];
    // 4. offsets = exclusive prefix sum over tiles; chunk c of tile t starts after chunks < c of that tile.
    int64_t total = 0;
    for (int64_t t = 0; t < n_tiles; ++t) {
        tile_offsets[t] = total;
        for (int c = 0; c < k; ++c) {
            int64_t& x = cnt[size_t(c) * size_t(n_tiles) + size_t(t)];
            const int64_t v = x;
            x = total;
            total += v;
        }
    }
    tile_offsets[n_tiles] = total;
    return total;
}

void isect_fill(IsectPlan& plan, int64_t* flatten_ids) {
    const int k = plan.nchunks;
    const int64_t m = plan.n_visible, n_tiles = plan.n_tiles;
#pragma omp parallel for num_threads(k) schedule(static, 1)
    for (int c = 0; c < k; ++c) {
        int64_t* cur = plan.cursor.data() + size_t(c) * size_t(n_tiles);
        for (int64_t i = chunk_lo(m, k, c); i < chunk_lo(m, k, c + 1); ++i) {
            const int64_t g = plan.order[i];
            for_each_tile(plan, g, [&](int64_t t) { flatten_ids[cur[t]++] = g; });
        }
    }
}

#define EIGS_INSTANTIATE_PROJ(S)                                                                              \
    template void project_forward<S>(int64_t, const S*, const S*, const S*, const S*, const S*, int64_t,      \
                                     const Camera<S>&, S*, S*, S*, S*, int32_t*, int);                        \
    template void project_backward<S>(int64_t, const S*, const S*, const S*, const Camera<S>&, const int32_t*, \
                                      const S*, const S*, S*, S*, S*, int);                                   \
    template int64_t isect_plan<S>(const BinInputs<S>&, const S*, const int32_t*, int64_t*, IsectPlan&, int);

EIGS_INSTANTIATE_PROJ(float)
EIGS_INSTANTIATE_PROJ(double)

}  // namespace eigs

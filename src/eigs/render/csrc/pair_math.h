// Per-pair math of the Gaussian rasterizer: the one place where the numerically sensitive steps of
// forward and backward compositing live (shared by the CPU kernels and any future CUDA kernel).
//
// Conventions: a pixel centre is (j + 0.5, i + 0.5); d = pixel - mean2d; the conic (a, b, c) is the upper
// triangle of the inverse 2-D covariance, sigma = 0.5 (a dx^2 + c dy^2) + b dx dy.  Gradients are named v_*.
// Everything here is always-inline so that it is compiled (and vectorised) with the ISA of the caller.
// Build flags: never -ffast-math; -ffp-contract=off keeps forward and backward bit-identical across ISAs.
#pragma once

#include <cmath>
#include <cstdint>
#include <type_traits>
#include <utility>

#define EIGS_INLINE inline __attribute__((always_inline))

// The lane vectors below are wider than the baseline ISA's registers; every function taking them is always-inline,
// so no vector crosses a call boundary and GCC's note on the changed ABI does not apply.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace eigs {

// A vector of N lanes of S (GCC vector extension): lane-wise IEEE arithmetic, the same results as the scalar
// code lane by lane (comparisons give a mask vector of same-width integers, 0 or -1).  The pair functions below
// are templates that take either a scalar S or such a vector, so that a kernel written with explicit vectors (the
// backward) runs the very same operations as one written with scalars and `omp simd` (the forward).
template <typename S, int N>
struct LaneVec {
    typedef S type __attribute__((vector_size(N * sizeof(S))));
};

// The lane type of a scalar (itself) or of a lane vector.
template <typename S, bool = std::is_arithmetic_v<S>>
struct LaneOf {
    using type = S;
};
template <typename S>
struct LaneOf<S, false> {
    using type = std::remove_cv_t<std::remove_reference_t<decltype(std::declval<S>()[0])>>;
};

// The constant x as an S (scalar) or in every lane (vector); the same value as S(x) lane by lane.
template <typename S>
EIGS_INLINE S cst(double x) {
    using E = typename LaneOf<S>::type;
    if constexpr (std::is_arithmetic_v<S>)
        return S(x);
    else
        return S{} + E(x);
}

// Guards and thresholds (docs/rasterizer.md, "Semantics").
constexpr double kAlphaMax = 0.99;            // alpha = min(kAlphaMax, o * G); no gradient when clamped
constexpr double kAlphaMin = 1.0 / 255.0;     // skip the pair when alpha < kAlphaMin
constexpr double kTransMin = 1e-4;            // stop before a Gaussian that would make T * (1 - alpha) < kTransMin
constexpr double kMinOneMinusAlpha = 1e-6;    // floor on 1 - alpha in the backward division
constexpr double kSigmaMax = 30.0;            // exp(-30) * 1 < kAlphaMin: clamping sigma here changes no decision
constexpr int kTile = 16;                     // tile side in pixels; one tile row is one AVX-512 vector of floats
constexpr int kTilePix = kTile * kTile;

// exp(x) for x <= 0 (the only use here).  float: Cody-Waite range reduction plus a degree-6 polynomial
// (relative error ~1e-7), branch-free so that the compositing loops vectorise; double: std::exp (exact path
// used by gradcheck).
EIGS_INLINE float exp_neg(float x) {
    x = x > -87.0f ? x : -87.0f;  // 2^n stays a normal number
    const float magic = 12582912.0f;  // 1.5 * 2^23: adding it rounds to the nearest integer
    const float t = x * 1.44269504088896341f + magic;
    const float n = t - magic;
    const float r = (x - n * 0.693359375f) - n * (-2.12194440e-4f);
    float p = 1.9875691500e-4f;
    p = p * r + 1.3981999507e-3f;
    p = p * r + 8.3334519073e-3f;
    p = p * r + 4.1665795894e-2f;
    p = p * r + 1.6666665459e-1f;
    p = p * r + 5.0000001201e-1f;
    p = p * (r * r) + r + 1.0f;
    // the low mantissa bits of t hold n: 2^n = bits ((n + 127) << 23)
    const int32_t e = (__builtin_bit_cast(int32_t, t) - __builtin_bit_cast(int32_t, magic) + 127) << 23;
    return p * __builtin_bit_cast(float, e);
}

EIGS_INLINE double exp_neg(double x) { return std::exp(x); }

// The same two functions lane by lane on a lane vector (float: the identical operation sequence, vectorised;
// double: std::exp per lane).
template <typename V>
EIGS_INLINE V exp_neg(V x) {
    using E = typename LaneOf<V>::type;
    if constexpr (std::is_same_v<E, float>) {
        using I = decltype(x < x);  // lanes of int32
        x = x > cst<V>(-87.0f) ? x : cst<V>(-87.0f);
        const V magic = cst<V>(12582912.0f);
        const V t = x * cst<V>(1.44269504088896341f) + magic;
        const V n = t - magic;
        const V r = (x - n * cst<V>(0.693359375f)) - n * cst<V>(-2.12194440e-4f);
        V p = cst<V>(1.9875691500e-4f);
        p = p * r + cst<V>(1.3981999507e-3f);
        p = p * r + cst<V>(8.3334519073e-3f);
        p = p * r + cst<V>(4.1665795894e-2f);
        p = p * r + cst<V>(1.6666665459e-1f);
        p = p * r + cst<V>(5.0000001201e-1f);
        p = p * (r * r) + r + cst<V>(1.0f);
        const I e = (__builtin_bit_cast(I, t) - __builtin_bit_cast(int32_t, 12582912.0f) + 127) << 23;
        return p * __builtin_bit_cast(V, e);
    } else {
        V out;
        for (int l = 0; l < int(sizeof(V) / sizeof(E)); ++l) out[l] = exp_neg(E(x[l]));
        return out;
    }
}

// sigma of a pair from its parts ca dx dx, cc dy dy, cb dx and dy: a kernel may compute the parts that do not
// change along a row or a column once (the backward hoists ca dx dx and cb dx out of its row loop); the
// operations, and so the result, are those of pair_sigma.  Arguments may mix scalars and lane vectors.
template <typename A, typename B, typename C, typename D>
EIGS_INLINE auto pair_sigma_parts(A cadxdx, B ccdydy, C cbdx, D dy) {
    using R = decltype(cadxdx + ccdydy + cbdx * dy);
    return cst<R>(0.5) * (cadxdx + ccdydy) + cbdx * dy;
}

// sigma of a pair (may be slightly negative through rounding; such pairs are skipped).
template <typename S>
EIGS_INLINE S pair_sigma(S ca, S cb, S cc, S dx, S dy) {
    return pair_sigma_parts(ca * dx * dx, cc * dy * dy, cb * dx, dy);
}

// Gaussian falloff G = exp(-sigma), with sigma clamped to [0, kSigmaMax] before the exp.
template <typename S>
EIGS_INLINE S pair_falloff(S sigma) {
    S s = sigma > cst<S>(0) ? sigma : cst<S>(0);
    s = s < cst<S>(kSigmaMax) ? s : cst<S>(kSigmaMax);
    return exp_neg(-s);
}

// Unclamped alpha o * G.
template <typename S>
EIGS_INLINE S pair_raw_alpha(S opacity, S falloff) {
    return opacity * falloff;
}

// alpha = min(kAlphaMax, o * G) (ternary min: vectorises and keeps IEEE semantics).
template <typename S>
EIGS_INLINE S pair_alpha(S raw) {
    return raw < cst<S>(kAlphaMax) ? raw : cst<S>(kAlphaMax);
}

// Whether a pair takes part at all: sigma >= 0 and alpha >= kAlphaMin.  Since kAlphaMax > kAlphaMin,
// min(kAlphaMax, raw) >= kAlphaMin  <=>  raw >= kAlphaMin; testing the raw value is the same decision and lets
// GCC vectorise the loop (a compare of the clamped value defeats its if-conversion).
template <typename S>
EIGS_INLINE auto pair_valid(S sigma, S raw) {
    return (sigma >= cst<S>(0)) & (raw >= cst<S>(kAlphaMin));
}

// Whether compositing alpha onto transmittance T terminates the pixel (exclusive: the Gaussian is not added).
template <typename S>
EIGS_INLINE bool pair_terminates(S T, S alpha) {
    return T * (S(1) - alpha) < S(kTransMin);
}

// Whether the gradient flows through the alpha clamp (torch.clamp semantics: raw <= max passes).
template <typename S>
EIGS_INLINE auto pair_unclamped(S raw) {
    return raw <= cst<S>(kAlphaMax);
}

// 1 / (1 - alpha) with the backward floor.
template <typename S>
EIGS_INLINE S pair_inv_one_minus(S alpha) {
    const S om = cst<S>(1) - alpha;
    return cst<S>(1) / (om > cst<S>(kMinOneMinusAlpha) ? om : cst<S>(kMinOneMinusAlpha));
}

// Backward of one pair through alpha = min(kAlphaMax, o G), G = exp(-sigma), given v_alpha = dL/dalpha:
//   v_opacity = G v_alpha and v_sigma = -o G v_alpha = -raw v_alpha where the clamp passes the gradient
//   (`unclamped`, a bool or a lane mask), else 0 for both.
template <typename S, typename M>
EIGS_INLINE void pair_alpha_vjp(S raw, S falloff, S v_alpha, M unclamped, S& v_sigma, S& v_opacity) {
    v_sigma = unclamped ? -raw * v_alpha : cst<S>(0);
    v_opacity = unclamped ? falloff * v_alpha : cst<S>(0);
}

// sigma = 0.5 (a dx^2 + c dy^2) + b dx dy with d = pixel - mean2d, so per pair
//   v_conic += v_sigma (dx^2/2, dx dy, dy^2/2) and v_mean2d += v_sigma (-(a dx + b dy), -(b dx + c dy)).
// Both are linear in the pair's v_sigma, so over any set of pairs of one Gaussian they follow from five moments
// of v_sigma: sxx = sum dx^2 v_sigma, sxy = sum dx dy v_sigma, syy = sum dy^2 v_sigma, sx = sum dx v_sigma,
// sy = sum dy v_sigma (the backward accumulates these instead of five products per pair).
// Writes out[0..4] = v_mean2d x, y, v_conic a, b, c.
template <typename S>
EIGS_INLINE void sigma_moments_vjp(S ca, S cb, S cc, S sxx, S sxy, S syy, S sx, S sy, S* out) {
    out[0] = -(ca * sx + cb * sy);
    out[1] = -(cb * sx + cc * sy);
    out[2] = S(0.5) * sxx;
    out[3] = sxy;
    out[4] = S(0.5) * syy;
}

}  // namespace eigs

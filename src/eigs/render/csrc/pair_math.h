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

#define EIGS_INLINE inline __attribute__((always_inline))

namespace eigs {

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

// sigma of a pair (may be slightly negative through rounding; such pairs are skipped).
template <typename S>
EIGS_INLINE S pair_sigma(S ca, S cb, S cc, S dx, S dy) {
    return S(0.5) * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
}

// Gaussian falloff G = exp(-sigma), with sigma clamped to [0, kSigmaMax] before the exp.
template <typename S>
EIGS_INLINE S pair_falloff(S sigma) {
    S s = sigma > S(0) ? sigma : S(0);
    s = s < S(kSigmaMax) ? s : S(kSigmaMax);
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
    return raw < S(kAlphaMax) ? raw : S(kAlphaMax);
}

// Whether a pair takes part at all: sigma >= 0 and alpha >= kAlphaMin.  Since kAlphaMax > kAlphaMin,
// min(kAlphaMax, raw) >= kAlphaMin  <=>  raw >= kAlphaMin; testing the raw value is the same decision and lets
// GCC vectorise the loop (a compare of the clamped value defeats its if-conversion).
template <typename S>
EIGS_INLINE bool pair_valid(S sigma, S raw) {
    return (sigma >= S(0)) & (raw >= S(kAlphaMin));
}

// Whether compositing alpha onto transmittance T terminates the pixel (exclusive: the Gaussian is not added).
template <typename S>
EIGS_INLINE bool pair_terminates(S T, S alpha) {
    return T * (S(1) - alpha) < S(kTransMin);
}

// Whether the gradient flows through the alpha clamp (torch.clamp semantics: raw <= max passes).
template <typename S>
EIGS_INLINE bool pair_unclamped(S raw) {
    return raw <= S(kAlphaMax);
}

// 1 / (1 - alpha) with the backward floor.
template <typename S>
EIGS_INLINE S pair_inv_one_minus(S alpha) {
    const S om = S(1) - alpha;
    return S(1) / (om > S(kMinOneMinusAlpha) ? om : S(kMinOneMinusAlpha));
}

// Backward of one valid pair, given v_alpha (dL/dalpha) and the falloff G:
//   v_opacity += G v_alpha (if unclamped); v_sigma = -raw v_alpha with raw = o G;
//   v_conic += v_sigma (dx^2/2, dx dy, dy^2/2); v_mean2d += v_sigma * (-(a dx + b dy), -(b dx + c dy)).
template <typename S>
struct PairGrad {
    S v_mx, v_my, v_a, v_b, v_c, v_o;
};

template <typename S>
EIGS_INLINE PairGrad<S> pair_backward(S ca, S cb, S cc, S raw, S falloff, S dx, S dy, S v_alpha,
                                      bool unclamped) {
    PairGrad<S> g;
    const S v_sigma = unclamped ? -raw * v_alpha : S(0);
    g.v_o = unclamped ? falloff * v_alpha : S(0);
    g.v_a = S(0.5) * dx * dx * v_sigma;
    g.v_b = dx * dy * v_sigma;
    g.v_c = S(0.5) * dy * dy * v_sigma;
    g.v_mx = -(ca * dx + cb * dy) * v_sigma;
    g.v_my = -(cb * dx + cc * dy) * v_sigma;
    return g;
}

}  // namespace eigs

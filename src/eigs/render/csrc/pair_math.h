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

// The lane templates, for the scalar kernels and the baseline ISA (no target attribute); the AVX2 and AVX-512
// backward include them again under their own targets (pair_lanes.inc says why).
#define EIGS_LANE_TARGET
#include "pair_lanes.inc"
#undef EIGS_LANE_TARGET

}  // namespace eigs

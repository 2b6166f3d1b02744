/*
 * rng.h — a counter-based random number generator: every random number is a
 * pure function of (seed, stream, counter), so any pixel of any frame can be
 * regenerated without replaying the others, and results do not depend on the
 * thread schedule. The mixer is the PCG output permutation chained over the
 * inputs (Jarzynski and Olano 2020, "Hash Functions for GPU Rendering").
 */
#ifndef HUSH_CORE_RNG_H
#define HUSH_CORE_RNG_H

#include <stdint.h>

static inline uint32_t hush_pcg_hash(uint32_t v) {
  const uint32_t state = v * 747796405u + 2891336453u;
  const uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
  return (word >> 22u) ^ word;
}

/* A 32-bit random value for (seed, stream, counter). */
static inline uint32_t hush_rng_u32(uint32_t seed, uint32_t stream, uint32_t counter) {
  return hush_pcg_hash(hush_pcg_hash(hush_pcg_hash(seed) ^ stream) ^ counter);
}

/* Uniform float in [0, 1) with 24 random bits. */
static inline float hush_rng_float(uint32_t seed, uint32_t stream, uint32_t counter) {
  return (float)(hush_rng_u32(seed, stream, counter) >> 8) * (1.0f / 16777216.0f);
}

/* lowbias32 (Wellons): a fast integer hash with good avalanche, for
 * choices that must be a function of their inputs (not of the thread
 * count): bmfr's fit noise, the renderer's random gradient pixel. */
static inline uint32_t hush_hash32(uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

#endif

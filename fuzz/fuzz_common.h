/*
 * fuzz_common.h — what the API fuzzers (fuzz_filter.c, fuzz_psf.c) share:
 * the input as a byte stream that reads 0 past its end (a short input is a
 * plain configuration), a hash for made-up pixel values, and OpenMP workers
 * that sleep when idle (each input runs once on 1 thread and once on 3,
 * which on a 2-core machine otherwise spins most of the time).
 */
#ifndef HUSH_FUZZ_COMMON_H
#define HUSH_FUZZ_COMMON_H

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerInitialize(int *argc, char ***argv);

typedef struct fuzz_bytes {
  const uint8_t *p;
  size_t n;
} fuzz_bytes;

static inline unsigned fuzz_u8(fuzz_bytes *b) {
  if (!b->n) return 0;
  b->n--;
  return *b->p++;
}

static inline uint32_t fuzz_u32(fuzz_bytes *b) {
  uint32_t v = 0;
  for (int i = 0; i < 4; i++) v = v << 8 | fuzz_u8(b);
  return v;
}

/* A hash of (seed, i) in [0, 1). */
static inline float fuzz_hash01(uint32_t seed, uint32_t i) {
  uint32_t h = seed * 0x9e3779b9u ^ i * 0x85ebca6bu;
  h ^= h >> 16;
  h *= 0x7feb352du;
  h ^= h >> 15;
  h *= 0x846ca68bu;
  h ^= h >> 16;
  return (float)(h >> 8) / 16777216.0f;
}

int LLVMFuzzerInitialize(int *argc, char ***argv) {
  (void)argc;
  (void)argv;
  setenv("KMP_BLOCKTIME", "0", 0);
  setenv("OMP_WAIT_POLICY", "passive", 0);
  return 0;
}

#endif

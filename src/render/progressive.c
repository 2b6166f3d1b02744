/*
 * progressive.c — the rotating, stratified pixel pattern of the fewer than
 * one sample per pixel mode (see progressive.h).
 */
#include "render/progressive.h"

#include <math.h>
#include <string.h>

/* Entry (x, y) of the n x n Bayer matrix, n a power of two:
 * M_2n(x, y) = 4 M_n(x mod n, y mod n) + M_2(x / n, y / n), M_2 = [0 2; 3 1].
 * The coarsest level lands in the lowest bits, so the first 4 ranks fall in
 * different quadrants, the first 16 in different sub-quadrants, and so on. */
static uint32_t bayer(uint32_t x, uint32_t y, uint32_t n) {
  uint32_t v = 0;
  for (uint32_t bit = 1; bit < n; bit <<= 1) {
    const uint32_t xb = (x & bit) != 0, yb = (y & bit) != 0;
    v = (v << 2) | ((xb ^ yb) << 1) | yb;
  }
  return v; /* the finest level, taken first, ends in the highest bits */
}

int hush__progressive_init_km(hush_progressive *p, uint32_t k, uint32_t m) {
  memset(p, 0, sizeof *p);
  if (k < 1 || k > HUSH_PROGRESSIVE_MAX_K || m < 1 || m > k * k) return 0;
  p->k = k;
  p->m = m;
  uint32_t n = 1;
  while (n < k) n <<= 1;
  /* The Bayer values of the k x k corner, compressed to ranks 0 .. k^2-1 in
   * their order: for k a power of two they are the Bayer matrix itself. */
  for (uint32_t i = 0; i < k * k; i++) {
    const uint32_t v = bayer(i % k, i / k, n);
    uint32_t rank = 0;
    for (uint32_t j = 0; j < k * k; j++)
      if (bayer(j % k, j / k, n) < v) rank++;
    p->rank[i] = (uint8_t)rank;
  }
  return 1;
}

int hush__progressive_init(hush_progressive *p, double fraction) {
  memset(p, 0, sizeof *p);
  if (!(fraction > 0.0 && fraction <= 1.0)) return 0;
  for (uint32_t k = 1; k <= HUSH_PROGRESSIVE_MAX_K; k++) {
    const double share = fraction * (double)(k * k);
    const double m = floor(share + 0.5);
    if (m >= 1.0 && fabs(m / (double)(k * k) - fraction) <= 1e-4)
      return hush__progressive_init_km(p, k, (uint32_t)m);
  }
  return 0;
}

uint32_t hush__progressive_cycle(const hush_progressive *p) {
  const uint32_t n = p->k * p->k;
  return n % p->m == 0 ? n / p->m : 0;
}

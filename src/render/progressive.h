/*
 * progressive.h — fewer than one sample per pixel: which pixels a frame
 * traces (svgf-progressive-dundr-2018.md §4.2). The image is cut into k x k
 * blocks aligned at pixel (0, 0); every frame traces the same m positions of
 * every block, and the positions rotate from frame to frame, so that
 *
 *   - the fraction traced per frame is m / k^2 (exactly, in whole blocks);
 *   - over k^2 frames every pixel is traced exactly m times, and when m
 *     divides k^2, exactly once in every k^2 / m consecutive frames (the
 *     cycle);
 *   - consecutive frames' positions are spread over the block (stratified):
 *     the positions are ranked by the Bayer (ordered dither) matrix of the
 *     next power of two >= k, so any run of consecutive ranks is spread
 *     evenly rather than clumped in one corner.
 *
 * Frame f traces the positions of ranks (f * m + j) mod k^2, j = 0 .. m-1.
 * Example: F = 1/4 gives k = 2, m = 1, the Bayer ranks
 *     0 2
 *     3 1
 * so frame 0 traces the top-left pixel of each 2x2 block, frame 1 the
 * bottom-right, frame 2 the top-right, frame 3 the bottom-left, frame 4 the
 * top-left again. Everything is a pure function of (fraction, x, y, frame).
 */
#ifndef HUSH_RENDER_PROGRESSIVE_H
#define HUSH_RENDER_PROGRESSIVE_H

#include <stdint.h>

#define HUSH_PROGRESSIVE_MAX_K 16u

typedef struct hush_progressive {
  uint32_t k;              /* block edge, 1 .. HUSH_PROGRESSIVE_MAX_K */
  uint32_t m;              /* pixels traced per block and frame, 1 .. k^2 */
  uint8_t rank[HUSH_PROGRESSIVE_MAX_K * HUSH_PROGRESSIVE_MAX_K]; /* of (bx, by) at by * k + bx */
} hush_progressive;

/* The smallest block k <= 16 with fraction = m / k^2 (within 1e-4): 0.25 gives
 * 2x2 blocks and 1 pixel, 0.5 gives 2x2 and 2, 0.1 gives 10x10 and 10, 1
 * gives 1x1 and 1. Returns 0 for a fraction outside (0, 1] or with no such
 * k (0.3 works, 10x10 and 30; 0.123 does not). */
int hush__progressive_init(hush_progressive *p, double fraction);

/* The same pattern from k and m directly (1 <= k <= 16, 1 <= m <= k^2);
 * returns 0 otherwise. */
int hush__progressive_init_km(hush_progressive *p, uint32_t k, uint32_t m);

/* Whether frame `frame` traces pixel (x, y). */
static inline int hush__progressive_traced(const hush_progressive *p, uint32_t x, uint32_t y,
                                           uint32_t frame) {
  const uint32_t n = p->k * p->k;
  const uint32_t r = p->rank[(y % p->k) * p->k + x % p->k];
  const uint32_t start = (uint32_t)(((uint64_t)frame * p->m) % n);
  return (r + n - start) % n < p->m;
}

/* Frames in which every pixel is traced exactly once: k^2 / m when m divides
 * k^2, else 0 (each pixel is traced m times in every k^2 frames). */
uint32_t hush__progressive_cycle(const hush_progressive *p);

#endif

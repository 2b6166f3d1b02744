/*
 * blocks.h — BMFR's block grid (bmfr-koskela-2019.md §3.5 and §6.1): the
 * frame is cut into non-overlapping B x B blocks on a grid displaced every
 * frame by one of 16 offsets, so block edges move and the second
 * accumulation averages them away. Blocks overhanging the image read it
 * mirrored (as the published code's margin blocks), so every block fits B^2
 * samples and no thin sliver of a block is fitted from a few pixels.
 */
#ifndef HUSH_FILTERS_BMFR_BLOCKS_H
#define HUSH_FILTERS_BMFR_BLOCKS_H

#include <stdint.h>

#define BMFR_OFFSET_COUNT 16

/* The grid offset of a frame, each in [0, B): the centres of a 4x4
 * stratification of [0, B)^2, visited in the order of the 4x4 Bayer matrix
 * so that consecutive frames are far apart; period 16 frames. With
 * displace == 0 the offset is (0, 0). */
void hush__bmfr_block_offset(uint64_t frame, int block, int displace, int *ox, int *oy);

/* The grid over a width x height image for an offset: blocks start at
 * x0 + k B (x0 = ox - B when ox > 0, else 0), likewise in y. */
typedef struct bmfr_grid {
  int block;      /* B */
  int x0, y0;     /* top-left of block (0, 0), may be negative */
  int nx, ny;     /* blocks across and down */
  int width, height;
} bmfr_grid;

void hush__bmfr_grid(bmfr_grid *g, int width, int height, int block, int ox, int oy);

/* x reflected into [0, size) about the image edges (..., 1, 0 | 0, 1, ...,
 * size-1 | size-1, ...), for any x. */
static inline int hush__bmfr_mirror(int x, int size) {
  if (size <= 1) return 0;
  const int period = 2 * size;
  x %= period;
  if (x < 0) x += period;
  return x < size ? x : period - 1 - x;
}

#endif

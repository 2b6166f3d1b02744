/*
 * blocks.c — BMFR's displaced block grid (see blocks.h;
 * bmfr-koskela-2019.md §3.5, §6.1).
 */
#include "filters/bmfr/blocks.h"

/* 4x4 Bayer matrix: entry = the frame (mod 16) that visits that cell. */
static const uint8_t bayer4[4][4] = {
    {0, 8, 2, 10},
    {12, 4, 14, 6},
    {3, 11, 1, 9},
    {15, 7, 13, 5},
};

void hush__bmfr_block_offset(uint64_t frame, int block, int displace, int *ox, int *oy) {
  *ox = 0;
  *oy = 0;
  if (!displace) return;
  const int k = (int)(frame % BMFR_OFFSET_COUNT);
  for (int cy = 0; cy < 4; cy++)
    for (int cx = 0; cx < 4; cx++)
      if (bayer4[cy][cx] == k) {
        /* cell centre: (2 c + 1) B / 8, in [0, B) */
        *ox = (2 * cx + 1) * block / 8;
        *oy = (2 * cy + 1) * block / 8;
      }
}

void hush__bmfr_grid(bmfr_grid *g, int width, int height, int block, int ox, int oy) {
  g->block = block;
  g->width = width;
  g->height = height;
  g->x0 = ox > 0 ? ox - block : 0;
  g->y0 = oy > 0 ? oy - block : 0;
  g->nx = (width - g->x0 + block - 1) / block;
  g->ny = (height - g->y0 + block - 1) / block;
}

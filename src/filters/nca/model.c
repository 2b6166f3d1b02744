/*
 * model.c — one iteration of the neural cellular automaton (Higginson 2023
 * §2.4.1, eq. 2.15-2.17) on planar float images: the inference path of the
 * "nca" filter.
 *
 * Per row: the 3x3 perception filters are separable, so each channel is
 * first summed vertically into two padded rows (smooth [1 2 1] and
 * difference [-1 0 1]); Gaussian, Laplacian and both Sobels are then short
 * horizontal combinations of those rows. The 39 x 9 product runs on chunks
 * of CHUNK pixels whose perception fits in L1, one channel at a time over
 * the pixels, so every inner loop is a branch-free loop over x.
 */
#include "filters/nca/model.h"

#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#define CHUNK 128

const float hush__nca_kernel_gauss[9] = {1.f / 16, 2.f / 16, 1.f / 16, 2.f / 16, 4.f / 16,
                                         2.f / 16, 1.f / 16, 2.f / 16, 1.f / 16};
const float hush__nca_kernel_laplace[9] = {1.f / 16, 2.f / 16,   1.f / 16, 2.f / 16, -12.f / 16,
                                           2.f / 16, 1.f / 16,   2.f / 16, 1.f / 16};
const float hush__nca_kernel_sobel_x[9] = {-1.f / 8, 0.f, 1.f / 8, -2.f / 8, 0.f,
                                           2.f / 8,  -1.f / 8, 0.f, 1.f / 8};
const float hush__nca_kernel_sobel_y[9] = {-1.f / 8, -2.f / 8, -1.f / 8, 0.f,    0.f,
                                           0.f,      1.f / 8,  2.f / 8,  1.f / 8};

/* Per thread: smooth and difference rows (w + 2 each, padded) for 9
 * channels, perception of one chunk (39 x CHUNK), update sums (9 x CHUNK). */
static size_t scratch_per_thread(uint32_t width) {
  return (size_t)HUSH_NCA_CHANNELS * 2 * (width + 2) +
         (size_t)(HUSH_NCA_PERCEPTION + HUSH_NCA_CHANNELS) * CHUNK;
}

size_t hush__nca_scratch_floats(uint32_t width, int threads) {
  return scratch_per_thread(width) * (size_t)(threads > 0 ? threads : 1);
}

/* Vertical [1 2 1] and [-1 0 1] sums of rows ym, y, yp of one channel into
 * v1 + 1 and v2 + 1, with the edge value repeated at index 0 and w + 1. */
static void vertical_sums(const float *restrict up, const float *restrict mid,
                          const float *restrict down, uint32_t w, float *restrict v1,
                          float *restrict v2) {
  for (uint32_t x = 0; x < w; x++) {
    v1[x + 1] = up[x] + 2.0f * mid[x] + down[x];
    v2[x + 1] = down[x] - up[x];
  }
  v1[0] = v1[1];
  v2[0] = v2[1];
  v1[w + 1] = v1[w];
  v2[w + 1] = v2[w];
}

/* Perception of pixels x0 .. x0 + n - 1 of one row into p[k * CHUNK + i]. */
static void perceive_chunk(const float *const row[HUSH_NCA_CHANNELS], const float *sums,
                           uint32_t w, uint32_t x0, uint32_t n, float *restrict p) {
  for (int c = 0; c < HUSH_NCA_CHANNELS; c++) {
    /* padded sums: index x0 + i + 1 is pixel x0 + i; l, m, r = x - 1, x, x + 1 */
    const float *v1 = sums + (size_t)c * 2 * (w + 2) + x0;
    const float *v2 = v1 + (w + 2);
    const float *restrict v1l = v1, *restrict v1m = v1 + 1, *restrict v1r = v1 + 2;
    const float *restrict v2l = v2, *restrict v2m = v2 + 1, *restrict v2r = v2 + 2;
    const float *restrict s = row[c] + x0;
    float *restrict ps = p + (size_t)(HUSH_NCA_P_STATE + c) * CHUNK;
    float *restrict pl = p + (size_t)(HUSH_NCA_P_LAPLACE + c) * CHUNK;
    float *restrict px = p + (size_t)(HUSH_NCA_P_SOBEL_X + c) * CHUNK;
    float *restrict py = p + (size_t)(HUSH_NCA_P_SOBEL_Y + c) * CHUNK;
    for (uint32_t i = 0; i < n; i++) {
      const float g = (v1l[i] + 2.0f * v1m[i] + v1r[i]) * (1.0f / 16);
      ps[i] = s[i];
      pl[i] = g - s[i];
      px[i] = (v1r[i] - v1l[i]) * (1.0f / 8);
      py[i] = (v2l[i] + 2.0f * v2m[i] + v2r[i]) * (1.0f / 8);
    }
    if (c < 3) {
      float *restrict pg = p + (size_t)(HUSH_NCA_P_GAUSS + c) * CHUNK;
      for (uint32_t i = 0; i < n; i++) pg[i] = pl[i] + s[i];
    }
  }
}

/* One vector register of floats (GCC/Clang vector extension): 16 with
 * AVX-512, else 8 (one AVX register, or two SSE ones). */
#ifdef __AVX512F__
#define LANES 16
#else
#define LANES 8
#endif
typedef float vf __attribute__((vector_size(LANES * 4)));

/* dst = src + sigmoid(p W) + bias for n pixels of a chunk. The 39 x 9
 * product is register-blocked: for LANES pixels at a time the 9 sums stay in
 * registers while the 39 perception values stream past, so each load feeds
 * 9 multiply-adds (a plain loop per output channel reloads and stores its
 * sum for every k and is bound by L1 traffic). p is padded to a multiple
 * of LANES pixels (the tail lanes are computed and dropped). */
static void update_chunk(const hush_nca_weights *wt, const float *restrict p,
                         const float *const row[HUSH_NCA_CHANNELS],
                         float *const out[HUSH_NCA_CHANNELS], uint32_t x0, uint32_t n,
                         float *restrict z) {
  for (uint32_t i0 = 0; i0 < n; i0 += LANES) {
    vf acc[HUSH_NCA_CHANNELS];
    for (int j = 0; j < HUSH_NCA_CHANNELS; j++) acc[j] = (vf){0};
    for (int k = 0; k < HUSH_NCA_PERCEPTION; k++) {
      vf pk;
      __builtin_memcpy(&pk, p + (size_t)k * CHUNK + i0, sizeof pk);
      const float *wk = wt->w + k * HUSH_NCA_CHANNELS;
      for (int j = 0; j < HUSH_NCA_CHANNELS; j++) acc[j] += wk[j] * pk;
    }
    for (int j = 0; j < HUSH_NCA_CHANNELS; j++)
      __builtin_memcpy(z + (size_t)j * CHUNK + i0, &acc[j], sizeof acc[j]);
  }
  for (int j = 0; j < HUSH_NCA_CHANNELS; j++) {
    const float *restrict zj = z + (size_t)j * CHUNK;
    const float b = wt->bias[j];
    const float *restrict s = row[j] + x0;
    float *restrict d = out[j] + x0;
    for (uint32_t i = 0; i < n; i++) d[i] = s[i] + hush__nca_sigmoid(zj[i]) + b;
  }
}

void hush__nca_step(const hush_nca_weights *wt, const float *const src[HUSH_NCA_CHANNELS],
                    float *const dst[HUSH_NCA_CHANNELS], uint32_t width, uint32_t height,
                    float *scratch, int threads) {
  const size_t per_thread = scratch_per_thread(width);
  const long h = (long)height;
#pragma omp parallel for num_threads(threads) schedule(static)
  for (long y = 0; y < h; y++) {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    float *sums = scratch + per_thread * (size_t)tid;
    float *p = sums + (size_t)HUSH_NCA_CHANNELS * 2 * (width + 2);
    float *z = p + (size_t)HUSH_NCA_PERCEPTION * CHUNK;
    const size_t ym = (size_t)(y > 0 ? y - 1 : 0), yc = (size_t)y;
    const size_t yp = (size_t)(y + 1 < h ? y + 1 : h - 1);
    const float *row[HUSH_NCA_CHANNELS];
    float *out[HUSH_NCA_CHANNELS];
    for (int c = 0; c < HUSH_NCA_CHANNELS; c++) {
      float *v1 = sums + (size_t)c * 2 * (width + 2);
      vertical_sums(src[c] + ym * width, src[c] + yc * width, src[c] + yp * width, width, v1,
                    v1 + width + 2);
      row[c] = src[c] + yc * width;
      out[c] = dst[c] + yc * width;
    }
    for (uint32_t x0 = 0; x0 < width; x0 += CHUNK) {
      const uint32_t n = width - x0 < CHUNK ? width - x0 : CHUNK;
      perceive_chunk(row, sums, width, x0, n, p);
      update_chunk(wt, p, row, out, x0, n, z);
    }
  }
}

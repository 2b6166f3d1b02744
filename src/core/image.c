/*
 * image.c — planar float buffers and the import/export between caller views
 * (strided, float32 or float16, interleaved) and planes. Import is also where
 * NaN/Inf input is caught, once, before any filter sees it.
 */
#include "core/image.h"

#include "core/device.h"
#include "core/half.h"

#include <float.h>
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

/*
 * Where in a 4 KiB page each allocation starts. aligned_alloc gives every
 * large buffer the same page offset, so pixel x of every plane of a frame
 * (same size, same offset) falls in the same L1 set, and a loop streaming
 * more planes than the cache has ways (the a-trous: 9 planes at 5 tap rows
 * read, 8 written) evicts its own lines; loads also alias stores 4 KiB
 * apart. Consecutive allocations therefore start 5 cache lines further on,
 * in a cycle of 13 (65 lines, 4160 bytes, so no two of a cycle share a
 * page offset). Measured: an a-trous level 12-20 % faster at steps 4-16
 * (docs/svgf-speed.md). Only addresses move; no result depends on it. The
 * counter is atomic, so concurrent allocations stay safe; it is the one
 * piece of process-wide state here and holds no data.
 */
#define STAGGER_LINES 5u
#define STAGGER_CYCLE 13u
static atomic_uint stagger_next;

/* The calling thread's allocation cap (hush__alloc_cap_open), per thread
 * so that filters committed on other threads keep their own. */
static _Thread_local struct {
  size_t left;
  int open, refused;
  hush_device device;
  const char *why;
} alloc_cap;

void hush__alloc_cap_open(hush_device device, size_t bytes, const char *why) {
  alloc_cap.left = bytes;
  alloc_cap.open = 1;
  alloc_cap.refused = 0;
  alloc_cap.device = device;
  alloc_cap.why = why;
}

size_t hush__alloc_cap_left(void) { return alloc_cap.left; }

int hush__alloc_cap_close(void) {
  alloc_cap.open = 0;
  return alloc_cap.refused;
}

/* Takes `bytes` from the open cap, if any; 0 when the cap refuses them. */
static int cap_take(size_t bytes) {
  if (!alloc_cap.open) return 1;
  if (bytes > alloc_cap.left) {
    /* recorded here, first, so that the device's error names the cap and
     * not the caller's "out of memory" that follows */
    if (!alloc_cap.refused)
      hush__fail(alloc_cap.device, HUSH_ERROR_OUT_OF_MEMORY, "%s", alloc_cap.why);
    alloc_cap.refused = 1;
    return 0;
  }
  alloc_cap.left -= bytes;
  return 1;
}

void *hush__alloc_counted(size_t count, size_t size) {
  if (count == 0 || size == 0 || count > SIZE_MAX / size) return NULL;
  return cap_take(count * size) ? calloc(count, size) : NULL;
}

float *hush__alloc_floats(size_t n) {
  const size_t slack = HUSH_ALIGN + STAGGER_LINES * STAGGER_CYCLE * 64u;
  if (n == 0 || n > (SIZE_MAX - 2 * slack - HUSH_ALIGN) / sizeof(float)) return NULL;
  const size_t bytes = (n * sizeof(float) + HUSH_ALIGN - 1) / HUSH_ALIGN * HUSH_ALIGN;
  if (!cap_take(bytes + slack)) return NULL;
  /* calloc, not aligned_alloc and memset: a large block comes as fresh
   * zero pages, which take memory only as the filter writes them */
  char *base = calloc(1, bytes + slack + HUSH_ALIGN);
  if (!base) return NULL;
  /* the HUSH_ALIGN bytes before the aligned start hold base for
   * hush__free_floats */
  const unsigned k = atomic_fetch_add_explicit(&stagger_next, 1u, memory_order_relaxed) %
                     STAGGER_CYCLE;
  const uintptr_t aligned =
      ((uintptr_t)base + 2 * HUSH_ALIGN - 1) / HUSH_ALIGN * HUSH_ALIGN; /* >= base + 64 */
  char *p = base + (aligned - (uintptr_t)base) + (size_t)k * STAGGER_LINES * 64u;
  memcpy(p - sizeof base, &base, sizeof base);
  return (float *)p;
}

void hush__free_floats(float *p) {
  if (!p) return;
  void *base;
  memcpy(&base, (char *)p - sizeof base, sizeof base);
  free(base);
}

hush_status hush__planar_init(hush_device device, hush_planar *img, int channels, uint32_t width,
                              uint32_t height) {
  memset(img, 0, sizeof *img);
  if (channels < 1 || channels > 4 || width == 0 || height == 0)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "planar image %dx%d with %d channels",
                      (int)width, (int)height, channels);
  const size_t n = (size_t)width * height;
  for (int c = 0; c < channels; c++) {
    img->plane[c] = hush__alloc_floats(n);
    if (!img->plane[c]) {
      hush__planar_free(img);
      return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for a %ux%u image",
                        width, height);
    }
  }
  img->channels = channels;
  img->width = width;
  img->height = height;
  return HUSH_OK;
}

void hush__planar_free(hush_planar *img) {
  for (int c = 0; c < 4; c++) hush__free_floats(img->plane[c]);
  memset(img, 0, sizeof *img);
}

int hush_format_channels(hush_format format) {
  switch (format) {
  case HUSH_FORMAT_FLOAT: case HUSH_FORMAT_HALF: return 1;
  case HUSH_FORMAT_FLOAT2: case HUSH_FORMAT_HALF2: return 2;
  case HUSH_FORMAT_FLOAT3: case HUSH_FORMAT_HALF3: return 3;
  case HUSH_FORMAT_FLOAT4: case HUSH_FORMAT_HALF4: return 4;
  default: return 0;
  }
}

size_t hush__format_element_size(hush_format format) {
  switch (format) {
  case HUSH_FORMAT_FLOAT: case HUSH_FORMAT_FLOAT2: case HUSH_FORMAT_FLOAT3: case HUSH_FORMAT_FLOAT4:
    return 4;
  case HUSH_FORMAT_HALF: case HUSH_FORMAT_HALF2: case HUSH_FORMAT_HALF3: case HUSH_FORMAT_HALF4:
    return 2;
  default: return 0;
  }
}

size_t hush_format_pixel_size(hush_format format) {
  return hush__format_element_size(format) * (size_t)hush_format_channels(format);
}

size_t hush__view_pixel_stride(const hush_image_view *v) {
  return v->pixel_stride ? v->pixel_stride : hush_format_pixel_size(v->format);
}

size_t hush__view_row_stride(const hush_image_view *v) {
  return v->row_stride ? v->row_stride : (size_t)v->width * hush__view_pixel_stride(v);
}

hush_status hush__view_validate(hush_device device, const hush_image_view *v, const char *what,
                                int min_channels, int exact) {
  if (!v) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "%s: view is NULL", what);
  if (!v->data) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "%s: data is NULL", what);
  const int ch = hush_format_channels(v->format);
  if (ch == 0)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "%s: invalid format %d", what,
                      (int)v->format);
  if (exact && ch != min_channels)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "%s: needs exactly %d channel(s), the view has %d", what, min_channels, ch);
  if (ch < min_channels)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "%s: needs at least %d channel(s), the view has %d", what, min_channels, ch);
  if (v->width == 0 || v->height == 0 || v->width > 65536 || v->height > 65536)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "%s: size %ux%u is outside 1..65536", what, v->width, v->height);
  const size_t elem = hush__format_element_size(v->format);
  const size_t ps = hush__view_pixel_stride(v);
  const size_t rs = hush__view_row_stride(v);
  if (ps % elem || rs % elem || v->byte_offset % elem)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "%s: strides and offset must be multiples of %zu bytes", what, elem);
  if (ps < hush_format_pixel_size(v->format))
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "%s: pixel stride %zu is smaller than a pixel (%zu bytes)", what, ps,
                      hush_format_pixel_size(v->format));
  if (v->height > 1 && rs < ps * v->width)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT,
                      "%s: row stride %zu is smaller than a row (%zu bytes): rows overlap", what,
                      rs, ps * v->width);
  return HUSH_OK;
}

#if defined(__GNUC__)
#  define HUSH_IMAGE_INLINE inline __attribute__((always_inline))
#else
#  define HUSH_IMAGE_INLINE inline
#endif

/* The first nc channels of w interleaved pixels of sf floats each into nc
 * planes. sf and nc are constants at each call (always inlined), so each
 * pixel is one group of constant-offset loads, which vectorises. */
static HUSH_IMAGE_INLINE void deinterleave_f32(const float *restrict rf, const size_t sf,
                                               const int nc, uint32_t w,
                                               float *const restrict *out) {
  float *restrict o0 = out[0];
  float *restrict o1 = nc > 1 ? out[1] : NULL;
  float *restrict o2 = nc > 2 ? out[2] : NULL;
  float *restrict o3 = nc > 3 ? out[3] : NULL;
  for (uint32_t x = 0; x < w; x++) {
    const float *p = rf + (size_t)x * sf;
    o0[x] = p[0];
    if (nc > 1) o1[x] = p[1];
    if (nc > 2) o2[x] = p[2];
    if (nc > 3) o3[x] = p[3];
  }
}

/* One row of a view into planes. The float path reads through a float
 * pointer when the row is aligned (the common case), so the compiler can
 * vectorise the strided loads; anything else goes through memcpy. */
static void import_row(const hush_image_view *v, size_t ps, size_t rs, uint32_t y, int nc,
                       float *const *out) {
  const char *row = (const char *)v->data + v->byte_offset + (size_t)y * rs;
  const uint32_t w = v->width;
  if (hush__format_element_size(v->format) == 2) {
    for (uint32_t x = 0; x < w; x++)
      for (int c = 0; c < nc; c++) {
        uint16_t h;
        memcpy(&h, row + (size_t)x * ps + 2 * (size_t)c, 2);
        out[c][x] = hush__half_to_float(h);
      }
    return;
  }
  if ((uintptr_t)row % sizeof(float) == 0) {
    const float *rf = (const float *)(const void *)row;
    const size_t sf = ps / sizeof(float);
    /* the usual layouts with a constant stride: the compiler turns the
     * interleaved loads into vector shuffles (a runtime stride makes them
     * scalar or gathers); one pass over the row for every channel */
    if (sf == 1) {
      memcpy(out[0], rf, (size_t)w * sizeof(float));
      return;
    }
    if (sf == 2 && nc == 2) { deinterleave_f32(rf, 2, 2, w, out); return; }
    if (sf == 2 && nc == 1) { deinterleave_f32(rf, 2, 1, w, out); return; }
    if (sf == 3 && nc == 3) { deinterleave_f32(rf, 3, 3, w, out); return; }
    if (sf == 3 && nc == 1) { deinterleave_f32(rf, 3, 1, w, out); return; }
    if (sf == 4 && nc == 4) { deinterleave_f32(rf, 4, 4, w, out); return; }
    if (sf == 4 && nc == 3) { deinterleave_f32(rf, 4, 3, w, out); return; }
    if (sf == 4 && nc == 1) { deinterleave_f32(rf, 4, 1, w, out); return; }
    for (int c = 0; c < nc; c++) {
      float *o = out[c];
      for (uint32_t x = 0; x < w; x++) o[x] = rf[(size_t)x * sf + (size_t)c];
    }
    return;
  }
  for (uint32_t x = 0; x < w; x++)
    for (int c = 0; c < nc; c++) memcpy(&out[c][x], row + (size_t)x * ps + 4 * (size_t)c, 4);
}

int hush__normals_odd(const float *a, const float *b, const float *c, size_t n) {
  int odd = 0;
#pragma omp simd reduction(| : odd)
  for (size_t x = 0; x < n; x++) {
    const float d = a[x] * a[x] + b[x] * b[x] + c[x] * c[x];
    const int unit = fabsf(d - 1.0f) <= HUSH_UNIT_TOLERANCE;
    odd |= (unit ^ 1) & ((a[x] != 0.0f) | (b[x] != 0.0f) | (c[x] != 0.0f));
  }
  return odd;
}

/* Values beyond HUSH_INPUT_MAX (Inf included) in one row of planes: a
 * branch-free count (NaN fails the comparison, so it counts too). */
static size_t count_nonfinite(float *const *planes, int nc, uint32_t w) {
  size_t bad = 0;
  for (int c = 0; c < nc; c++) {
    const float *p = planes[c];
    for (uint32_t x = 0; x < w; x++) bad += !(fabsf(p[x]) <= HUSH_INPUT_MAX);
  }
  return bad;
}

#if defined(__AVX512F__) && defined(__x86_64__)
static HUSH_IMAGE_INLINE size_t count_nonfinite16(__m512 v) {
  /* NaN fails the comparison, so it counts too */
  const __mmask16 ok = _mm512_cmp_ps_mask(_mm512_abs_ps(v), _mm512_set1_ps(HUSH_INPUT_MAX), _CMP_LE_OQ);
  return (size_t)__builtin_popcount((unsigned)(__mmask16)~ok);
}

/* The three channels of 16 pixels of 3 interleaved floats at p: lane j of
 * channel k is element 3 j + k of the 48 in a|b|c, those below 32 picked
 * from a|b, then the rest from c (the constants hoist out of the callers'
 * loops). */
static HUSH_IMAGE_INLINE void rgb16(const float *p, __m512 r[3]) {
  const __m512i ia0 = _mm512_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 30, 0, 0, 0, 0, 0);
  const __m512i ic0 = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 17, 20, 23, 26, 29);
  const __m512i ia1 = _mm512_setr_epi32(1, 4, 7, 10, 13, 16, 19, 22, 25, 28, 31, 0, 0, 0, 0, 0);
  const __m512i ic1 = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 18, 21, 24, 27, 30);
  const __m512i ia2 = _mm512_setr_epi32(2, 5, 8, 11, 14, 17, 20, 23, 26, 29, 0, 0, 0, 0, 0, 0);
  const __m512i ic2 = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 16, 19, 22, 25, 28, 31);
  const __m512 a = _mm512_loadu_ps(p), b = _mm512_loadu_ps(p + 16), c = _mm512_loadu_ps(p + 32);
  r[0] = _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, ia0, b), ic0, c);
  r[1] = _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, ia1, b), ic1, c);
  r[2] = _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, ia2, b), ic2, c);
}

/* hush__normals_odd's test of 16 normals (its arithmetic, unfused), as a
 * mask of the odd ones. */
static HUSH_IMAGE_INLINE __mmask16 normals_odd16(__m512 a, __m512 b, __m512 c) {
  const __m512 d = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(a, a), _mm512_mul_ps(b, b)),
                                 _mm512_mul_ps(c, c));
  const __mmask16 unit = _mm512_cmp_ps_mask(_mm512_abs_ps(_mm512_sub_ps(d, _mm512_set1_ps(1.0f))),
                                            _mm512_set1_ps(HUSH_UNIT_TOLERANCE), _CMP_LE_OQ);
  const __m512 z = _mm512_setzero_ps();
  const __mmask16 nonzero = _mm512_cmp_ps_mask(a, z, _CMP_NEQ_UQ) |
                            _mm512_cmp_ps_mask(b, z, _CMP_NEQ_UQ) |
                            _mm512_cmp_ps_mask(c, z, _CMP_NEQ_UQ);
  return (__mmask16)~unit & nonzero;
}

/*
 * A row of w floats (w a multiple of 16) of one, two or three interleaved
 * channels into 64-byte aligned planes with streaming stores: the import
 * writes 4 bytes per channel and pixel, and ordinary stores would first
 * read each line for ownership (a third more memory traffic) only to push
 * it out again, as a 1280x720 frame's planes do not stay in the cache
 * until the next stage. Measured: the import stage 4.5 -> 3.8 ms per
 * 1280x720 frame on 2 threads (docs/svgf-speed.md). Returns the count of
 * NaN/Inf values, taken from the registers.
 */
static size_t stream_row(const float *restrict rf, int nc, uint32_t w, float *const *out,
                         int *odd) {
  size_t bad = 0;
  if (nc == 1) {
    for (uint32_t x = 0; x < w; x += 16) {
      const __m512 a = _mm512_loadu_ps(rf + x);
      bad += count_nonfinite16(a);
      _mm512_stream_ps(out[0] + x, a);
    }
    return bad;
  }
  if (nc == 2) {
    /* lane j of channel k is element 2 j + k of the 32 in a|b */
    const __m512i e0 = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
    const __m512i e1 = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31);
    for (uint32_t x = 0; x < w; x += 16) {
      const float *p = rf + 2 * (size_t)x;
      const __m512 a = _mm512_loadu_ps(p), b = _mm512_loadu_ps(p + 16);
      const __m512 r0 = _mm512_permutex2var_ps(a, e0, b), r1 = _mm512_permutex2var_ps(a, e1, b);
      bad += count_nonfinite16(r0) + count_nonfinite16(r1);
      _mm512_stream_ps(out[0] + x, r0);
      _mm512_stream_ps(out[1] + x, r1);
    }
    return bad;
  }
  __mmask16 odd_lanes = 0;
  for (uint32_t x = 0; x < w; x += 16) {
    __m512 r[3];
    rgb16(rf + 3 * (size_t)x, r);
    bad += count_nonfinite16(r[0]) + count_nonfinite16(r[1]) + count_nonfinite16(r[2]);
    if (odd) odd_lanes |= normals_odd16(r[0], r[1], r[2]);
    _mm512_stream_ps(out[0] + x, r[0]);
    _mm512_stream_ps(out[1] + x, r[1]);
    _mm512_stream_ps(out[2] + x, r[2]);
  }
  if (odd) *odd = odd_lanes != 0;
  return bad;
}

/* Whether stream_row takes row y of v into out: float32, 1 to 3 channels
 * packed, aligned planes, a width of whole vectors. */
static int streamable(const hush_image_view *v, int nc, const float *row, float *const *out) {
  const size_t ps = hush__view_pixel_stride(v);
  if (hush__format_element_size(v->format) != 4 || (uintptr_t)row % sizeof(float) != 0 ||
      v->width % 16 != 0 || ps != (size_t)nc * sizeof(float) || nc > 3)
    return 0;
  for (int c = 0; c < nc; c++)
    if ((uintptr_t)out[c] % 64 != 0) return 0;
  return 1;
}
#endif

#if defined(__x86_64__) && !defined(__AVX512F__)
/*
 * stream_row's streaming stores for builds without AVX-512 (x86-64-v3,
 * the baseline): a row goes through an L1 buffer span by span (the same
 * import_row, so the same values), its NaN/Inf counted there, optionally
 * divided by max(divisor, floor) as albedo.c's demodulation divides, then
 * streamed to the planes: ordinary stores would first read each line for
 * ownership only to push it out again. Measured on the x86-64-v3 build
 * (docs/svgf-speed.md, tenth round).
 */
#define IMPORT_SPAN 256

static int spans_streamable(const hush_image_view *v, int nc, float *const *out) {
  if (hush__format_element_size(v->format) != 4 || nc > 3) return 0;
  for (int c = 0; c < nc; c++)
    if ((uintptr_t)out[c] % 32 != 0) return 0;
  return 1;
}

static void stream_span(float *restrict dst, const float *restrict src, uint32_t n) {
  uint32_t x = 0;
#if defined(__AVX__)
  for (; x + 8 <= n; x += 8) _mm256_stream_ps(dst + x, _mm256_load_ps(src + x));
#else
  for (; x + 4 <= n; x += 4) _mm_stream_ps(dst + x, _mm_load_ps(src + x));
#endif
  for (; x < n; x++) dst[x] = src[x];
}

static size_t import_spans(const hush_image_view *v, uint32_t y, int nc, float *const *out,
                           const float *const *divisor, float floor) {
  const size_t ps = hush__view_pixel_stride(v), rs = hush__view_row_stride(v);
  float buf[3][IMPORT_SPAN] __attribute__((aligned(64)));
  float *const tmp[3] = {buf[0], buf[1], buf[2]};
  size_t bad = 0;
  for (uint32_t x0 = 0; x0 < v->width; x0 += IMPORT_SPAN) {
    const uint32_t n = v->width - x0 < IMPORT_SPAN ? v->width - x0 : IMPORT_SPAN;
    hush_image_view span = *v;
    span.width = n;
    span.byte_offset += (size_t)x0 * ps;
    import_row(&span, ps, rs, y, nc, tmp);
    bad += count_nonfinite(tmp, nc, n);
    for (int c = 0; c < nc; c++) {
      if (divisor) {
        const float *restrict d = divisor[c] + x0;
        float *restrict t = tmp[c];
        for (uint32_t x = 0; x < n; x++) t[x] = t[x] / (d[x] > floor ? d[x] : floor);
      }
      stream_span(out[c] + x0, tmp[c], n);
    }
  }
  _mm_sfence(); /* streamed stores are weakly ordered: visible before the row is done */
  return bad;
}

#if defined(__AVX2__)
/*
 * AVX2 builds: stream_row's one pass for rows of 1 to 3 packed float
 * channels (8 pixels a step: the channels picked out by blends and a
 * permute, NaN/Inf counted from the registers, streamed), optionally each
 * channel divided by max(divisor, floor) as hush__view_import_row_divided's
 * AVX-512 loop. import_spans made three passes over an L1 buffer for the
 * same values. The pixels past the last whole vector go through the
 * scalar loop.
 */
static HUSH_IMAGE_INLINE size_t count_nonfinite8(__m256 v) {
  /* NaN fails the comparison, so it counts too */
  const __m256 a = _mm256_and_ps(v, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff)));
  const int ok = _mm256_movemask_ps(_mm256_cmp_ps(a, _mm256_set1_ps(HUSH_INPUT_MAX), _CMP_LE_OQ));
  return (size_t)__builtin_popcount((unsigned)~ok & 0xffu);
}

/* Channel k of 8 pixels of 3 floats (a|b|c: 24 floats): element 3j + k
 * sits in lane (3j + k) mod 8, a different lane for each j, so one blend
 * of a, b and c and one permute gather them. */
static HUSH_IMAGE_INLINE __m256 rgb8_channel(__m256 a, __m256 b, __m256 c, const int k) {
  if (k == 0)
    return _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(a, b, 0x92), c, 0x24),
                                    _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5));
  if (k == 1)
    return _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(a, b, 0x24), c, 0x49),
                                    _mm256_setr_epi32(1, 4, 7, 2, 5, 0, 3, 6));
  return _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(a, b, 0x49), c, 0x92),
                                  _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7));
}

static size_t stream_row8(const float *restrict rf, int nc, uint32_t w, float *const *out,
                          const float *const *divisor, float floor) {
  const uint32_t w8 = w & ~7u;
  const __m256 fl = _mm256_set1_ps(floor);
  size_t bad = 0;
  uint32_t x = 0;
  if (nc == 1) {
    for (; x < w8; x += 8) {
      const __m256 a = _mm256_loadu_ps(rf + x);
      bad += count_nonfinite8(a);
      _mm256_stream_ps(out[0] + x, a);
    }
  } else if (nc == 2) {
    for (; x < w8; x += 8) {
      const float *p = rf + 2 * (size_t)x;
      const __m256 a = _mm256_loadu_ps(p), b = _mm256_loadu_ps(p + 8);
      /* per 128-bit lane [x0 x1 x4 x5 | x2 x3 x6 x7], then the pairs in order */
      const __m256 r0 = _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(_mm256_shuffle_ps(a, b, 0x88)), 0xd8));
      const __m256 r1 = _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(_mm256_shuffle_ps(a, b, 0xdd)), 0xd8));
      bad += count_nonfinite8(r0) + count_nonfinite8(r1);
      _mm256_stream_ps(out[0] + x, r0);
      _mm256_stream_ps(out[1] + x, r1);
    }
  } else {
    for (; x < w8; x += 8) {
      const float *p = rf + 3 * (size_t)x;
      const __m256 a = _mm256_loadu_ps(p), b = _mm256_loadu_ps(p + 8), c = _mm256_loadu_ps(p + 16);
      __m256 r0 = rgb8_channel(a, b, c, 0), r1 = rgb8_channel(a, b, c, 1),
             r2 = rgb8_channel(a, b, c, 2);
      bad += count_nonfinite8(r0) + count_nonfinite8(r1) + count_nonfinite8(r2);
      if (divisor) {
        /* vmaxps(d, floor) is `d > floor ? d : floor` (NaN gives floor) */
        r0 = _mm256_div_ps(r0, _mm256_max_ps(_mm256_loadu_ps(divisor[0] + x), fl));
        r1 = _mm256_div_ps(r1, _mm256_max_ps(_mm256_loadu_ps(divisor[1] + x), fl));
        r2 = _mm256_div_ps(r2, _mm256_max_ps(_mm256_loadu_ps(divisor[2] + x), fl));
      }
      _mm256_stream_ps(out[0] + x, r0);
      _mm256_stream_ps(out[1] + x, r1);
      _mm256_stream_ps(out[2] + x, r2);
    }
  }
  for (; x < w; x++)
    for (int c = 0; c < nc; c++) {
      float v = rf[(size_t)x * (size_t)nc + (size_t)c];
      bad += !(fabsf(v) <= HUSH_INPUT_MAX);
      if (divisor) v = v / (divisor[c][x] > floor ? divisor[c][x] : floor);
      out[c][x] = v;
    }
  _mm_sfence(); /* streamed stores are weakly ordered: visible before the row is done */
  return bad;
}

/* Whether stream_row8 takes row `row` of v: float32, 1 to 3 channels
 * packed, the row float-aligned, the planes 32-byte aligned. */
static int streamable8(const hush_image_view *v, int nc, const char *row, float *const *out) {
  if (hush__format_element_size(v->format) != 4 || nc > 3 || (uintptr_t)row % sizeof(float) != 0 ||
      hush__view_pixel_stride(v) != (size_t)nc * sizeof(float))
    return 0;
  for (int c = 0; c < nc; c++)
    if ((uintptr_t)out[c] % 32 != 0) return 0;
  return 1;
}
#endif
#endif

static size_t view_import_row(const hush_image_view *v, uint32_t y, hush_planar *dst,
                              int stream, int *odd) {
  const int nc = dst->channels;
  const uint32_t w = v->width;
  float *out[4];
  for (int c = 0; c < nc; c++) out[c] = dst->plane[c] + (size_t)y * w;
#if defined(__AVX512F__) && defined(__x86_64__)
  const char *row = (const char *)v->data + v->byte_offset + (size_t)y * hush__view_row_stride(v);
  if (stream && streamable(v, nc, (const float *)(const void *)row, out)) {
    /* the normals' test from the registers */
    const size_t bad = stream_row((const float *)(const void *)row, nc, w, out, nc == 3 ? odd : NULL);
    _mm_sfence(); /* streamed stores are weakly ordered: visible before the row is done */
    if (odd && nc != 3) *odd = 0;
    return bad;
  }
#endif
  size_t bad;
#if !defined(__AVX512F__) && defined(__x86_64__) && defined(__AVX2__)
  const char *row = (const char *)v->data + v->byte_offset + (size_t)y * hush__view_row_stride(v);
  if (stream && streamable8(v, nc, row, out))
    bad = stream_row8((const float *)(const void *)row, nc, w, out, NULL, 0.0f);
  else
#endif
#if !defined(__AVX512F__) && defined(__x86_64__)
  if (stream && spans_streamable(v, nc, out)) {
    bad = import_spans(v, y, nc, out, NULL, 0.0f);
  } else
#endif
  {
    (void)stream;
    import_row(v, hush__view_pixel_stride(v), hush__view_row_stride(v), y, nc, out);
    bad = count_nonfinite(out, nc, w);
  }
  /* the other paths read the row back for the normals' test (streamed rows
   * of the x86-64-v3 build, as the separate pass did) */
  if (odd) *odd = nc == 3 && hush__normals_odd(out[0], out[1], out[2], w);
  return bad;
}

size_t hush__view_import_row(const hush_image_view *v, uint32_t y, hush_planar *dst) {
  return view_import_row(v, y, dst, 1, NULL);
}

size_t hush__view_import_row_normals(const hush_image_view *v, uint32_t y, hush_planar *dst,
                                     int *odd) {
  return view_import_row(v, y, dst, 1, odd);
}

int hush__view_import_row_divided(const hush_image_view *v, uint32_t y, hush_planar *dst,
                                  const hush_planar *divisor, float floor, size_t *bad) {
#if defined(__x86_64__)
  const uint32_t w = v->width;
  float *out[3];
  const float *div[3];
  if (dst->channels != 3) return 0;
  for (int c = 0; c < 3; c++) {
    out[c] = dst->plane[c] + (size_t)y * w;
    div[c] = divisor->plane[c] + (size_t)y * w;
  }
#endif
#if defined(__AVX512F__) && defined(__x86_64__)
  const char *row = (const char *)v->data + v->byte_offset + (size_t)y * hush__view_row_stride(v);
  const float *rf = (const float *)(const void *)row;
  if (!streamable(v, 3, rf, out)) return 0;
  /* as stream_row's three channels, each divided by max(divisor, floor) */
  const __m512 fl = _mm512_set1_ps(floor);
  size_t n = 0;
  for (uint32_t x = 0; x < w; x += 16) {
    __m512 r[3];
    rgb16(rf + 3 * (size_t)x, r);
    const __m512 r0 = r[0], r1 = r[1], r2 = r[2];
    n += count_nonfinite16(r0) + count_nonfinite16(r1) + count_nonfinite16(r2);
    /* vmaxps(d, floor) is `d > floor ? d : floor` (NaN gives floor), as
     * albedo.c's scalar clamp */
    const __m512 d0 = _mm512_max_ps(_mm512_loadu_ps(div[0] + x), fl);
    const __m512 d1 = _mm512_max_ps(_mm512_loadu_ps(div[1] + x), fl);
    const __m512 d2 = _mm512_max_ps(_mm512_loadu_ps(div[2] + x), fl);
    _mm512_stream_ps(out[0] + x, _mm512_div_ps(r0, d0));
    _mm512_stream_ps(out[1] + x, _mm512_div_ps(r1, d1));
    _mm512_stream_ps(out[2] + x, _mm512_div_ps(r2, d2));
  }
  _mm_sfence();
  *bad = n;
  return 1;
#elif defined(__x86_64__)
#if defined(__AVX2__)
  const char *row = (const char *)v->data + v->byte_offset + (size_t)y * hush__view_row_stride(v);
  if (streamable8(v, 3, row, out)) {
    *bad = stream_row8((const float *)(const void *)row, 3, w, out, div, floor);
    return 1;
  }
#endif
  if (!spans_streamable(v, 3, out)) return 0;
  *bad = import_spans(v, y, 3, out, div, floor);
  return 1;
#else
  (void)v, (void)y, (void)dst, (void)divisor, (void)floor, (void)bad;
  return 0;
#endif
}

int hush__view_import_row_pair_divided(const hush_image_view *v, const hush_image_view *dv,
                                       uint32_t y, hush_planar *dst, hush_planar *divisor,
                                       float floor, int stream, size_t *bad,
                                       size_t *bad_divisor) {
#if defined(__AVX512F__) && defined(__x86_64__)
  const uint32_t w = v->width;
  if (dst->channels != 3 || divisor->channels != 3 || dv->width != w) return 0;
  float *out[3], *dout[3];
  for (int c = 0; c < 3; c++) {
    out[c] = dst->plane[c] + (size_t)y * w;
    dout[c] = divisor->plane[c] + (size_t)y * w;
  }
  const float *rf = (const float *)(const void *)((const char *)v->data + v->byte_offset +
                                                  (size_t)y * hush__view_row_stride(v));
  const float *df = (const float *)(const void *)((const char *)dv->data + dv->byte_offset +
                                                  (size_t)y * hush__view_row_stride(dv));
  if (!streamable(v, 3, rf, out) || !streamable(dv, 3, df, dout)) return 0;
  /* as stream_row's three channels (both views), then the division */
  const __m512 fl = _mm512_set1_ps(floor);
  size_t n = 0, nd = 0;
  for (uint32_t x = 0; x < w; x += 16) {
    __m512 d[3], r[3];
    rgb16(df + 3 * (size_t)x, d);
    nd += count_nonfinite16(d[0]) + count_nonfinite16(d[1]) + count_nonfinite16(d[2]);
    rgb16(rf + 3 * (size_t)x, r);
    n += count_nonfinite16(r[0]) + count_nonfinite16(r[1]) + count_nonfinite16(r[2]);
    /* vmaxps(d, floor) is `d > floor ? d : floor` (NaN gives floor), as
     * hush__view_import_row_divided */
    if (stream)
      for (int k = 0; k < 3; k++) {
        _mm512_stream_ps(dout[k] + x, d[k]);
        _mm512_stream_ps(out[k] + x, _mm512_div_ps(r[k], _mm512_max_ps(d[k], fl)));
      }
    else
      for (int k = 0; k < 3; k++) {
        _mm512_store_ps(dout[k] + x, d[k]);
        _mm512_store_ps(out[k] + x, _mm512_div_ps(r[k], _mm512_max_ps(d[k], fl)));
      }
  }
  if (stream) _mm_sfence();
  *bad = n;
  *bad_divisor = nd;
  return 1;
#else
  (void)v, (void)dv, (void)y, (void)dst, (void)divisor, (void)floor, (void)stream, (void)bad,
      (void)bad_divisor;
  return 0;
#endif
}

size_t hush__view_import_row_cached(const hush_image_view *v, uint32_t y, hush_planar *dst) {
  return view_import_row(v, y, dst, 0, NULL);
}

hush_status hush__view_import_nonfinite(hush_device device, const hush_image_view *v,
                                        const char *what, hush_planar *dst,
                                        hush_nonfinite_policy policy, size_t bad) {
  if (!bad) return HUSH_OK;
  /* Rare path: find the first bad pixel for the message and zero them all. */
  size_t first_bad = SIZE_MAX;
  const uint32_t w = v->width;
  const size_t n = (size_t)w * v->height;
  for (int c = 0; c < dst->channels; c++)
    for (size_t i = 0; i < n; i++)
      if (!(fabsf(dst->plane[c][i]) <= HUSH_INPUT_MAX)) {
        if (i < first_bad) first_bad = i;
        dst->plane[c][i] = 0.0f;
      }
  if (policy == HUSH_NONFINITE_ERROR)
    return hush__fail(device, HUSH_ERROR_NONFINITE,
                      "%s: %zu NaN/Inf value(s) or value(s) beyond +-%g, first at pixel (%zu, "
                      "%zu); set nonfinite=replace to use 0 instead",
                      what, bad, (double)HUSH_INPUT_MAX, first_bad % w, first_bad / w);
  return HUSH_OK;
}

hush_status hush__view_import(hush_device device, const hush_image_view *v, const char *what,
                              hush_planar *dst, hush_nonfinite_policy policy, size_t *replaced) {
  const uint32_t h = v->height;
  const int threads = device ? device->threads : 1;
  size_t bad = 0;
#pragma omp parallel for schedule(static) num_threads(threads) reduction(+ : bad)
  for (uint32_t y = 0; y < h; y++) bad += hush__view_import_row(v, y, dst);
  if (replaced) *replaced = bad;
  return hush__view_import_nonfinite(device, v, what, dst, policy, bad);
}

/* nc planes into the first nc channels of w interleaved pixels of sf
 * floats each (the others untouched); sf and nc constant at each call. */
static HUSH_IMAGE_INLINE void interleave_f32(const float *const *in, const size_t sf,
                                             const int nc, uint32_t w, float *restrict rf) {
  const float *restrict i0 = in[0];
  const float *restrict i1 = nc > 1 ? in[1] : NULL;
  const float *restrict i2 = nc > 2 ? in[2] : NULL;
  const float *restrict i3 = nc > 3 ? in[3] : NULL;
  for (uint32_t x = 0; x < w; x++) {
    float *p = rf + (size_t)x * sf;
    p[0] = i0[x];
    if (nc > 1) p[1] = i1[x];
    if (nc > 2) p[2] = i2[x];
    if (nc > 3) p[3] = i3[x];
  }
}

#if defined(__x86_64__) && (defined(__AVX512F__) || defined(__AVX2__))
/* Pixels [x0, x1) of three planes into an interleaved float row, plainly:
 * the streaming interleaves' ends. */
static void interleave3_plain(const float *const *in, uint32_t x0, uint32_t x1, float *rf) {
  for (uint32_t x = x0; x < x1; x++) {
    rf[3 * (size_t)x] = in[0][x];
    rf[3 * (size_t)x + 1] = in[1][x];
    rf[3 * (size_t)x + 2] = in[2][x];
  }
}

/* The first pixel whose output rf + 3 x lies on an `align`-byte boundary
 * (w if none), the pixels before it written plainly. */
static uint32_t interleave3_head(const float *const *in, uint32_t w, float *rf, uintptr_t align) {
  uint32_t x = 0;
  while (x < w && ((uintptr_t)(rf + 3 * (size_t)x) & (align - 1u)) != 0) x++;
  interleave3_plain(in, 0, x, rf);
  return x;
}
#endif

#if defined(__AVX512F__) && defined(__x86_64__)
/* Pixels x0.. of three planes into an interleaved float row with streaming
 * stores (see stream_row: the caller does not read the output back): the
 * pixels before the first 64-byte boundary of the output and after the
 * last whole group of 16 as plain stores. rf: 4-byte aligned. */
static void stream_interleave3(const float *const *in, uint32_t w, float *rf) {
  uint32_t x = interleave3_head(in, w, rf, 64);
  /* output element e = 3 j + k of a group is lane j of plane k: each output
   * vector takes planes 0 and 1 first, then plane 2 */
  const __m512i it0 = _mm512_setr_epi32(0, 16, 0, 1, 17, 0, 2, 18, 0, 3, 19, 0, 4, 20, 0, 5);
  const __m512i iu0 = _mm512_setr_epi32(0, 1, 16, 3, 4, 17, 6, 7, 18, 9, 10, 19, 12, 13, 20, 15);
  const __m512i it1 = _mm512_setr_epi32(21, 0, 6, 22, 0, 7, 23, 0, 8, 24, 0, 9, 25, 0, 10, 26);
  const __m512i iu1 = _mm512_setr_epi32(0, 21, 2, 3, 22, 5, 6, 23, 8, 9, 24, 11, 12, 25, 14, 15);
  const __m512i it2 = _mm512_setr_epi32(0, 11, 27, 0, 12, 28, 0, 13, 29, 0, 14, 30, 0, 15, 31, 0);
  const __m512i iu2 = _mm512_setr_epi32(26, 1, 2, 27, 4, 5, 28, 7, 8, 29, 10, 11, 30, 13, 14, 31);
  for (; x + 16 <= w; x += 16) {
    const __m512 r0 = _mm512_loadu_ps(in[0] + x), r1 = _mm512_loadu_ps(in[1] + x),
                 r2 = _mm512_loadu_ps(in[2] + x);
    float *p = rf + 3 * (size_t)x;
    _mm512_stream_ps(p, _mm512_permutex2var_ps(_mm512_permutex2var_ps(r0, it0, r1), iu0, r2));
    _mm512_stream_ps(p + 16, _mm512_permutex2var_ps(_mm512_permutex2var_ps(r0, it1, r1), iu1, r2));
    _mm512_stream_ps(p + 32, _mm512_permutex2var_ps(_mm512_permutex2var_ps(r0, it2, r1), iu2, r2));
  }
  interleave3_plain(in, x, w, rf);
  _mm_sfence();
}
#endif

#if defined(__AVX2__) && !defined(__AVX512F__) && defined(__x86_64__)
/* stream_interleave3 for AVX2 builds, 8 pixels a step: plane k permuted so
 * that lane (3 j + k) mod 8 holds its pixel j (the inverse of
 * rgb8_channel's permute), then each output vector blended from the three
 * (its lane l is element e = 8 v + l, plane e mod 3). The pixels before the
 * first 32-byte boundary of the output and after the last whole group of
 * 8 as plain stores. */
static void stream_interleave3_avx2(const float *const *in, uint32_t w, float *rf) {
  uint32_t x = interleave3_head(in, w, rf, 32);
  const __m256i p0 = _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5);
  const __m256i p1 = _mm256_setr_epi32(5, 0, 3, 6, 1, 4, 7, 2);
  const __m256i p2 = _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7);
  for (; x + 8 <= w; x += 8) {
    const __m256 a = _mm256_permutevar8x32_ps(_mm256_loadu_ps(in[0] + x), p0),
                 b = _mm256_permutevar8x32_ps(_mm256_loadu_ps(in[1] + x), p1),
                 c = _mm256_permutevar8x32_ps(_mm256_loadu_ps(in[2] + x), p2);
    float *p = rf + 3 * (size_t)x;
    _mm256_stream_ps(p, _mm256_blend_ps(_mm256_blend_ps(a, b, 0x92), c, 0x24));
    _mm256_stream_ps(p + 8, _mm256_blend_ps(_mm256_blend_ps(a, b, 0x24), c, 0x49));
    _mm256_stream_ps(p + 16, _mm256_blend_ps(_mm256_blend_ps(a, b, 0x49), c, 0x92));
  }
  interleave3_plain(in, x, w, rf);
  _mm_sfence();
}
#endif

void hush__view_export_span(const float *const *in, int nc, const hush_image_view *v,
                            uint32_t y, uint32_t x0, uint32_t w) {
  const size_t ps = hush__view_pixel_stride(v), rs = hush__view_row_stride(v);
  char *row = (char *)v->data + v->byte_offset + (size_t)y * rs + (size_t)x0 * ps;
  if (hush__format_element_size(v->format) == 2) {
    for (uint32_t x = 0; x < w; x++)
      for (int c = 0; c < nc; c++) {
        const uint16_t hv = hush__float_to_half_saturating(in[c][x]);
        memcpy(row + (size_t)x * ps + 2 * (size_t)c, &hv, 2);
      }
    return;
  }
  if ((uintptr_t)row % sizeof(float) == 0) {
    float *rf = (float *)(void *)row;
    const size_t sf = ps / sizeof(float);
    /* the usual layouts with a constant stride (see import_row) */
    if (sf == 1) { memcpy(rf, in[0], (size_t)w * sizeof(float)); return; }
#if defined(__AVX512F__) && defined(__x86_64__)
    if (sf == 3 && nc == 3 && w >= 32) { stream_interleave3(in, w, rf); return; }
#elif defined(__AVX2__) && defined(__x86_64__)
    if (sf == 3 && nc == 3 && w >= 16) { stream_interleave3_avx2(in, w, rf); return; }
#endif
    if (sf == 3 && nc == 3) { interleave_f32(in, 3, 3, w, rf); return; }
    if (sf == 4 && nc == 4) { interleave_f32(in, 4, 4, w, rf); return; }
    if (sf == 4 && nc == 3) { interleave_f32(in, 4, 3, w, rf); return; }
    for (int c = 0; c < nc; c++) {
      const float *p = in[c];
      for (uint32_t x = 0; x < w; x++) rf[(size_t)x * sf + (size_t)c] = p[x];
    }
    return;
  }
  for (uint32_t x = 0; x < w; x++)
    for (int c = 0; c < nc; c++) memcpy(row + (size_t)x * ps + 4 * (size_t)c, &in[c][x], 4);
}

void hush__view_export(const hush_planar *src, const hush_image_view *v, int threads) {
  const uint32_t h = v->height, w = v->width;
  const int nc = src->channels;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (uint32_t y = 0; y < h; y++) {
    const float *in[4] = {NULL, NULL, NULL, NULL};
    for (int c = 0; c < nc; c++) in[c] = src->plane[c] + (size_t)y * w;
    hush__view_export_span(in, nc, v, y, 0, w);
  }
}

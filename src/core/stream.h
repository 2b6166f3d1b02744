/*
 * stream.h — copies into buffers that no cache will hold until their next
 * reader: with non-temporal stores, a line is written without first being
 * read for ownership, so a frame-sized output costs its bytes once on the
 * memory bus instead of twice. For outputs written in one pass and read in a
 * later one (a whole frame of other traffic in between evicts them anyway).
 */
#ifndef HUSH_CORE_STREAM_H
#define HUSH_CORE_STREAM_H

#include "core/vecmath.h" /* HUSH_ALWAYS_INLINE */

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#if defined(__x86_64__)
#include <immintrin.h> /* SSE2 at least: part of x86-64 */
#endif

/* Asks for the cache line at p + bytes ahead of its use. Computed on
 * integers: the address may lie outside the object p points into (past a
 * row's or the frame's end, before a margin), which a prefetch does not
 * fault on but which a pointer could not be formed to. Always inlined: GCC
 * finds an out-of-line copy free of side effects and deletes its calls
 * (every prefetch of the reprojection plan was gone). */
static HUSH_ALWAYS_INLINE void hush__prefetch(const void *p, ptrdiff_t bytes) {
  __builtin_prefetch((const void *)((uintptr_t)p + (uintptr_t)bytes));
}

/* hush__prefetch of the same byte offset in each of planes[0..n-1]
 * (NULL: skipped): a row's streams, asked for together. */
static HUSH_ALWAYS_INLINE void hush__prefetch_planes(const float *const *planes, int n,
                                                     ptrdiff_t bytes) {
  for (int p = 0; p < n; p++)
    if (planes[p]) hush__prefetch(planes[p], bytes);
}

/* dst[0..bytes) = src[0..bytes) for bytes < 64: two overlapping copies of
 * a fixed size each (a branch on the size class), no loop. gcc turned the
 * variable-size memcpy this replaces into `rep movsl`, whose start-up
 * (tens of cycles, even for 0 bytes) the reprojection plan paid 14 times a
 * span of 256 pixels. */
static inline void hush__copy_small(char *d, const char *s, size_t bytes) {
  if (bytes >= 32) {
    memcpy(d, s, 32);
    memcpy(d + bytes - 32, s + bytes - 32, 32);
  } else if (bytes >= 16) {
    memcpy(d, s, 16);
    memcpy(d + bytes - 16, s + bytes - 16, 16);
  } else if (bytes >= 8) {
    memcpy(d, s, 8);
    memcpy(d + bytes - 8, s + bytes - 8, 8);
  } else if (bytes >= 4) {
    memcpy(d, s, 4);
    memcpy(d + bytes - 4, s + bytes - 4, 4);
  } else if (bytes) {
    d[0] = s[0];
    d[bytes / 2] = s[bytes / 2];
    d[bytes - 1] = s[bytes - 1];
  }
}

/* dst[0..bytes) = src[0..bytes): the whole 64-byte lines of dst streamed,
 * the partial ones at either end copied as usual. Streamed stores are
 * weakly ordered: call hush__stream_fence before another thread may read
 * dst. */
static inline void hush__stream_copy(void *dst, const void *src, size_t bytes) {
#if defined(__x86_64__)
  char *d = (char *)dst;
  const char *s = (const char *)src;
  const size_t head = (64u - (uintptr_t)d % 64u) % 64u;
  if (bytes < head + 64u) {
    memcpy(d, s, bytes);
    return;
  }
  hush__copy_small(d, s, head);
  d += head;
  s += head;
  bytes -= head;
  for (; bytes >= 64u; bytes -= 64u, d += 64, s += 64) {
#if defined(__AVX512F__)
    _mm512_stream_si512((void *)d, _mm512_loadu_si512((const void *)s));
#elif defined(__AVX__)
    _mm256_stream_si256((__m256i *)(void *)d, _mm256_loadu_si256((const __m256i *)(const void *)s));
    _mm256_stream_si256((__m256i *)(void *)(d + 32),
                        _mm256_loadu_si256((const __m256i *)(const void *)(s + 32)));
#else
    for (int q = 0; q < 64; q += 16)
      _mm_stream_si128((__m128i *)(void *)(d + q), _mm_loadu_si128((const __m128i *)(const void *)(s + q)));
#endif
  }
  hush__copy_small(d, s, bytes);
#else
  memcpy(dst, src, bytes);
#endif
}

/* Orders the streamed stores before what follows (another thread's reads
 * after a barrier). */
static inline void hush__stream_fence(void) {
#if defined(__x86_64__)
  _mm_sfence();
#endif
}

#endif

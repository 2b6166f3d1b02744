/*
 * stream.h — copies into buffers that no cache will hold until their next
 * reader: with non-temporal stores, a line is written without first being
 * read for ownership, so a frame-sized output costs its bytes once on the
 * memory bus instead of twice. For outputs written in one pass and read in a
 * later one (a whole frame of other traffic in between evicts them anyway).
 */
#ifndef HUSH_CORE_STREAM_H
#define HUSH_CORE_STREAM_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#if defined(__x86_64__)
#include <immintrin.h> /* SSE2 at least: part of x86-64 */
#endif

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
  memcpy(d, s, head);
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
  memcpy(d, s, bytes);
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

/*
 * svg.h — a growing text buffer, and a small line-plot writer that renders
 * series as an inline SVG document (axes, ticks at 1-2-5 steps or decades,
 * axis labels, a legend, dashed lines). The report's per-frame metric plots
 * are made with it, so the report needs no plotting library and no network.
 */
#ifndef HUSH_EVAL_SVG_H
#define HUSH_EVAL_SVG_H

#include <stddef.h>
#include <stdint.h>

#if defined(__GNUC__)
#  define HUSH_SVG_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#  define HUSH_SVG_PRINTF(a, b)
#endif

/* Text that grows as it is appended to. An allocation failure sets `failed`
 * and makes every later append a no-op, so writers check once at the end. */
typedef struct hush_strbuf {
  char *data; /* NUL-terminated when len > 0 */
  size_t len, cap;
  int failed;
} hush_strbuf;

void hush__strbuf_append(hush_strbuf *b, const char *text);
void hush__strbuf_printf(hush_strbuf *b, const char *fmt, ...) HUSH_SVG_PRINTF(2, 3);
/* Appends text with &, <, >, " and ' escaped, for HTML and SVG. */
void hush__strbuf_escape(hush_strbuf *b, const char *text);
void hush__strbuf_free(hush_strbuf *b);

typedef struct hush_svg_series {
  const char *name;     /* legend entry */
  const double *x, *y;  /* count points; a NaN y (or y <= 0 on a log axis) breaks the line */
  uint32_t count;
  const char *color;    /* CSS colour, "#1f77b4" */
  int dashed;
} hush_svg_series;

typedef struct hush_svg_plot {
  const char *title;
  const char *x_label, *y_label;
  int width, height;    /* pixels of the whole picture, legend included */
  int log_y;            /* 1: logarithmic y axis */
  const hush_svg_series *series;
  uint32_t series_count;
} hush_svg_plot;

/* Appends one <svg> element. With no finite point it still draws the axes
 * and says "no data". */
void hush__svg_line_plot(hush_strbuf *out, const hush_svg_plot *plot);

#endif

/*
 * svg.c — the text buffer and the line-plot writer of svg.h.
 *
 * A plot is a white picture: the plot area on the left, the legend in a
 * column of its own on the right (so it never hides a line), the title
 * above, the axis labels below and to the left. Axis limits are rounded
 * out to whole tick steps so the ticks land on the frame.
 */
#include "eval/svg.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------------ */
/* Text buffer                                                              */
/* ------------------------------------------------------------------------ */

static int strbuf_reserve(hush_strbuf *b, size_t extra) {
  if (b->failed) return 0;
  if (b->len + extra + 1 <= b->cap) return 1;
  size_t cap = b->cap ? b->cap : 4096;
  while (cap < b->len + extra + 1) cap *= 2;
  char *data = realloc(b->data, cap);
  if (!data) {
    b->failed = 1;
    return 0;
  }
  b->data = data;
  b->cap = cap;
  return 1;
}

void hush__strbuf_append(hush_strbuf *b, const char *text) {
  const size_t n = strlen(text);
  if (!strbuf_reserve(b, n)) return;
  memcpy(b->data + b->len, text, n + 1);
  b->len += n;
}

void hush__strbuf_printf(hush_strbuf *b, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  const int n = vsnprintf(NULL, 0, fmt, ap);
  va_end(ap);
  if (n < 0) {
    b->failed = 1;
    return;
  }
  if (!strbuf_reserve(b, (size_t)n)) return;
  va_start(ap, fmt);
  vsnprintf(b->data + b->len, (size_t)n + 1, fmt, ap);
  va_end(ap);
  b->len += (size_t)n;
}

void hush__strbuf_escape(hush_strbuf *b, const char *text) {
  for (const char *p = text; *p; p++) {
    switch (*p) {
    case '&': hush__strbuf_append(b, "&amp;"); break;
    case '<': hush__strbuf_append(b, "&lt;"); break;
    case '>': hush__strbuf_append(b, "&gt;"); break;
    case '"': hush__strbuf_append(b, "&quot;"); break;
    case '\'': hush__strbuf_append(b, "&#39;"); break;
    default: {
      const char c[2] = {*p, 0};
      hush__strbuf_append(b, c);
    }
    }
  }
}

void hush__strbuf_free(hush_strbuf *b) {
  free(b->data);
  memset(b, 0, sizeof *b);
}

/* ------------------------------------------------------------------------ */
/* Axes                                                                     */
/* ------------------------------------------------------------------------ */

#define MAX_TICKS 32

typedef struct axis {
  double lo, hi; /* limits (log10 of them on a log axis) */
  int log;
  double ticks[MAX_TICKS]; /* tick values, in data units */
  int tick_count;
  int decimals; /* for linear labels */
} axis;

/* 1, 2 or 5 times a power of ten, about range / target. */
static double nice_step(double range, int target) {
  const double raw = range / target;
  const double mag = pow(10.0, floor(log10(raw)));
  const double f = raw / mag;
  const double nice = f <= 1.0 ? 1.0 : f <= 2.0 ? 2.0 : f <= 5.0 ? 5.0 : 10.0;
  return nice * mag;
}

static void axis_linear(axis *a, double lo, double hi, int integer) {
  if (!(hi > lo)) {
    const double pad = lo != 0.0 ? fabs(lo) * 0.1 : 1.0;
    lo -= pad;
    hi += pad;
  }
  double step = nice_step(hi - lo, 5);
  if (integer && step < 1.0) step = 1.0;
  a->log = 0;
  a->lo = floor(lo / step + 1e-9) * step;
  a->hi = ceil(hi / step - 1e-9) * step;
  a->tick_count = 0;
  for (double t = a->lo; t <= a->hi + step * 0.5 && a->tick_count < MAX_TICKS; t += step)
    a->ticks[a->tick_count++] = fabs(t) < step * 1e-9 ? 0.0 : t;
  a->decimals = step >= 1.0 ? 0 : (int)ceil(-log10(step) - 1e-9);
}

/* Decades; with two decades or fewer, 2 and 5 times each too. */
static void axis_log(axis *a, double lo, double hi) {
  a->log = 1;
  a->lo = floor(log10(lo));
  a->hi = ceil(log10(hi));
  if (a->hi <= a->lo) a->hi = a->lo + 1.0;
  const int fine = a->hi - a->lo <= 2.0;
  a->tick_count = 0;
  for (double e = a->lo; e <= a->hi + 0.5 && a->tick_count < MAX_TICKS - 3; e += 1.0) {
    const double d = pow(10.0, e);
    a->ticks[a->tick_count++] = d;
    if (fine && e < a->hi - 0.5) {
      a->ticks[a->tick_count++] = 2.0 * d;
      a->ticks[a->tick_count++] = 5.0 * d;
    }
  }
}

/* Position in [0, 1] along the axis. */
static double axis_t(const axis *a, double v) {
  const double x = a->log ? log10(v) : v;
  return (x - a->lo) / (a->hi - a->lo);
}

static void axis_label(const axis *a, double v, char *buf, size_t size) {
  if (a->log || (v != 0.0 && (fabs(v) < 1e-3 || fabs(v) >= 1e6)))
    snprintf(buf, size, "%g", v);
  else
    snprintf(buf, size, "%.*f", a->decimals, v);
}

/* ------------------------------------------------------------------------ */
/* The plot                                                                 */
/* ------------------------------------------------------------------------ */

typedef struct frame_box {
  double left, top, right, bottom;
} frame_box;

static int usable(const hush_svg_plot *p, double x, double y) {
  return isfinite(x) && isfinite(y) && (!p->log_y || y > 0.0);
}

/* Data limits over every usable point; 0 when there is none. */
static int data_limits(const hush_svg_plot *p, double *x0, double *x1, double *y0, double *y1) {
  int any = 0;
  for (uint32_t s = 0; s < p->series_count; s++) {
    const hush_svg_series *se = &p->series[s];
    for (uint32_t i = 0; i < se->count; i++) {
      if (!usable(p, se->x[i], se->y[i])) continue;
      if (!any) {
        *x0 = *x1 = se->x[i];
        *y0 = *y1 = se->y[i];
        any = 1;
      }
      *x0 = fmin(*x0, se->x[i]);
      *x1 = fmax(*x1, se->x[i]);
      *y0 = fmin(*y0, se->y[i]);
      *y1 = fmax(*y1, se->y[i]);
    }
  }
  return any;
}

static void draw_axes(hush_strbuf *out, const hush_svg_plot *p, const frame_box *f,
                      const axis *ax, const axis *ay) {
  char label[64];
  for (int i = 0; i < ay->tick_count; i++) {
    const double y = f->bottom - axis_t(ay, ay->ticks[i]) * (f->bottom - f->top);
    axis_label(ay, ay->ticks[i], label, sizeof label);
    hush__strbuf_printf(out,
                        "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#e4e4e4\"/>"
                        "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\">%s</text>\n",
                        f->left, y, f->right, y, f->left - 5.0, y + 4.0, label);
  }
  for (int i = 0; i < ax->tick_count; i++) {
    const double x = f->left + axis_t(ax, ax->ticks[i]) * (f->right - f->left);
    axis_label(ax, ax->ticks[i], label, sizeof label);
    hush__strbuf_printf(out,
                        "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#444\"/>"
                        "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%s</text>\n",
                        x, f->bottom, x, f->bottom + 4.0, x, f->bottom + 16.0, label);
  }
  hush__strbuf_printf(out,
                      "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"none\" "
                      "stroke=\"#444\"/>\n",
                      f->left, f->top, f->right - f->left, f->bottom - f->top);
  if (p->x_label) {
    hush__strbuf_printf(out, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">",
                        (f->left + f->right) / 2.0, f->bottom + 32.0);
    hush__strbuf_escape(out, p->x_label);
    hush__strbuf_append(out, "</text>\n");
  }
  if (p->y_label) {
    const double cy = (f->top + f->bottom) / 2.0;
    hush__strbuf_printf(out,
                        "<text x=\"14\" y=\"%.1f\" text-anchor=\"middle\" "
                        "transform=\"rotate(-90 14 %.1f)\">",
                        cy, cy);
    hush__strbuf_escape(out, p->y_label);
    if (p->log_y) hush__strbuf_append(out, " (log scale)");
    hush__strbuf_append(out, "</text>\n");
  }
}

/* One <path> per series; an unusable point starts a new piece. Markers
 * when the points are few enough to tell apart, and always for a lone
 * point, which a line alone would not show. */
static void draw_series(hush_strbuf *out, const hush_svg_plot *p, const hush_svg_series *s,
                        const frame_box *f, const axis *ax, const axis *ay) {
  const double w = f->right - f->left, h = f->bottom - f->top;
  hush__strbuf_printf(out, "<path fill=\"none\" stroke=\"%s\" stroke-width=\"1.6\"%s d=\"",
                      s->color, s->dashed ? " stroke-dasharray=\"6 4\"" : "");
  int pen_down = 0;
  for (uint32_t i = 0; i < s->count; i++) {
    if (!usable(p, s->x[i], s->y[i])) {
      pen_down = 0;
      continue;
    }
    hush__strbuf_printf(out, "%c%.1f %.1f ", pen_down ? 'L' : 'M',
                        f->left + axis_t(ax, s->x[i]) * w, f->bottom - axis_t(ay, s->y[i]) * h);
    pen_down = 1;
  }
  hush__strbuf_append(out, "\"/>\n");
  if (s->dashed || s->count > 40) return;
  for (uint32_t i = 0; i < s->count; i++) {
    if (!usable(p, s->x[i], s->y[i])) continue;
    hush__strbuf_printf(out, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"2.2\" fill=\"%s\"/>",
                        f->left + axis_t(ax, s->x[i]) * w, f->bottom - axis_t(ay, s->y[i]) * h,
                        s->color);
  }
  hush__strbuf_append(out, "\n");
}

static void draw_legend(hush_strbuf *out, const hush_svg_plot *p, double x, double top) {
  for (uint32_t i = 0; i < p->series_count; i++) {
    const hush_svg_series *s = &p->series[i];
    const double y = top + 8.0 + 18.0 * i;
    hush__strbuf_printf(out,
                        "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\" "
                        "stroke-width=\"2\"%s/><text x=\"%.1f\" y=\"%.1f\">",
                        x, y, x + 22.0, y, s->color,
                        s->dashed ? " stroke-dasharray=\"6 4\"" : "", x + 28.0, y + 4.0);
    hush__strbuf_escape(out, s->name ? s->name : "");
    hush__strbuf_append(out, "</text>\n");
  }
}

void hush__svg_line_plot(hush_strbuf *out, const hush_svg_plot *p) {
  const int width = p->width > 200 ? p->width : 200;
  const int height = p->height > 120 ? p->height : 120;
  const frame_box f = {64.0, 28.0, width - 160.0, height - 44.0};

  hush__strbuf_printf(out,
                      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%d\" height=\"%d\" "
                      "viewBox=\"0 0 %d %d\" font-family=\"sans-serif\" font-size=\"11\">\n"
                      "<rect width=\"%d\" height=\"%d\" fill=\"#fff\"/>\n",
                      width, height, width, height, width, height);
  if (p->title) {
    hush__strbuf_printf(out, "<text x=\"%.1f\" y=\"17\" text-anchor=\"middle\" "
                             "font-size=\"13\" font-weight=\"bold\">",
                        (f.left + f.right) / 2.0);
    hush__strbuf_escape(out, p->title);
    hush__strbuf_append(out, "</text>\n");
  }

  double x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  const int any = data_limits(p, &x0, &x1, &y0, &y1);
  axis ax, ay;
  axis_linear(&ax, x0, x1, 1);
  if (p->log_y && any)
    axis_log(&ay, y0, y1);
  else
    axis_linear(&ay, y0, y1, 0);
  draw_axes(out, p, &f, &ax, &ay);
  if (!any) {
    hush__strbuf_printf(out, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" "
                             "fill=\"#888\">no data</text>\n",
                        (f.left + f.right) / 2.0, (f.top + f.bottom) / 2.0);
  } else {
    for (uint32_t i = 0; i < p->series_count; i++)
      draw_series(out, p, &p->series[i], &f, &ax, &ay);
  }
  draw_legend(out, p, f.right + 14.0, f.top);
  hush__strbuf_append(out, "</svg>\n");
}

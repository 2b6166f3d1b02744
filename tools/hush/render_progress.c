/*
 * render_progress.c — see render_progress.h.
 */
#include "render_progress.h"

#include "core/timer.h"

#include <stdio.h>

/* "42 s", "3 min 05 s", "2 h 07 min". */
static void duration(double s, char *buf, size_t size) {
  if (!(s >= 0.0)) s = 0.0;
  const unsigned long t = (unsigned long)(s + 0.5);
  if (t < 60)
    snprintf(buf, size, "%lu s", t);
  else if (t < 3600)
    snprintf(buf, size, "%lu min %02lu s", t / 60, t % 60);
  else
    snprintf(buf, size, "%lu h %02lu min", t / 3600, t / 60 % 60);
}

/* One report: on a terminal it replaces the last one (padded so a shorter
 * report leaves nothing behind), elsewhere it is a line of its own. */
static void report(render_progress *p, const char *text) {
  if (p->tty) {
    fprintf(stderr, "\r%-79s", text);
    p->line_open = 1;
  } else {
    fprintf(stderr, "%s\n", text);
  }
  fflush(stderr);
}

void render_progress_begin(render_progress *p, uint32_t frames, int tty, int quiet, int bar) {
  p->quiet = quiet;
  p->tty = tty;
  p->bar = bar;
  p->frames = frames;
  p->frame = 0;
  p->start_ms = hush__now_ms();
  p->frame_start_ms = p->start_ms;
  p->line_open = 0;
}

void render_progress_frame_start(render_progress *p, uint32_t frame) {
  p->frame = frame;
  p->frame_start_ms = hush__now_ms();
}

/* Mean wall seconds per finished frame, or a guess from the current one. */
static double seconds_per_frame(const render_progress *p, double frame_guess) {
  if (p->frame == 0) return frame_guess;
  return (p->frame_start_ms - p->start_ms) / 1000.0 / p->frame;
}

void render_progress_rows(render_progress *p, uint32_t rows_done, uint32_t rows) {
  if (p->quiet || !p->bar || rows == 0) return;
  const double el = (hush__now_ms() - p->frame_start_ms) / 1000.0;
  const double frame_left = rows_done ? el * (double)(rows - rows_done) / rows_done : 0.0;
  const double frame_total = rows_done ? el * (double)rows / rows_done : 0.0;
  const double left =
      frame_left + (double)(p->frames - p->frame - 1) * seconds_per_frame(p, frame_total);
  enum { WIDTH = 30 };
  char bar[WIDTH + 1], left_text[32], text[160];
  const int fill = (int)((double)WIDTH * rows_done / rows);
  for (int i = 0; i < WIDTH; i++) bar[i] = i < fill ? '#' : '.';
  bar[WIDTH] = '\0';
  duration(left, left_text, sizeof left_text);
  snprintf(text, sizeof text, "frame %u/%u [%s] %3.0f%%  %.0f s elapsed, %s left", p->frame + 1,
           p->frames, bar, 100.0 * rows_done / rows, el, left_text);
  report(p, text);
}

void render_progress_frame_done(render_progress *p, double render_seconds, double cpu_seconds,
                                uint64_t rays) {
  if (p->quiet) return;
  const double now = hush__now_ms();
  const uint32_t done = p->frame + 1;
  const double per_frame = (now - p->start_ms) / 1000.0 / done;
  const double mrays = render_seconds > 0.0 ? (double)rays / (render_seconds * 1e6) : 0.0;
  char left_text[32], cpu_text[32] = "", text[200];
  duration(per_frame * (double)(p->frames - done), left_text, sizeof left_text);
  if (cpu_seconds >= 0.0) snprintf(cpu_text, sizeof cpu_text, "  cpu %.3f s", cpu_seconds);
  snprintf(text, sizeof text, "frame %u/%u  render %.3f s  %.2f Mrays/s  %.3f s/frame  %s left%s",
           done, p->frames, render_seconds, mrays, per_frame, left_text, cpu_text);
  report(p, text);
}

void render_progress_break(render_progress *p) {
  if (!p->line_open) return;
  fputc('\n', stderr);
  p->line_open = 0;
}

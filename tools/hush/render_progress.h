/*
 * render_progress.h — progress of `hush render` on stderr: after every frame
 * "frame i/N", its render time, Mrays/s, the mean wall time per frame and the
 * time left; for references (a per-row bar) also while a frame renders. On a
 * terminal each report overwrites the last (\r); otherwise each is a line,
 * so logs stay readable. Nothing is printed when quiet.
 */
#ifndef HUSH_TOOLS_RENDER_PROGRESS_H
#define HUSH_TOOLS_RENDER_PROGRESS_H

#include <stdint.h>

typedef struct render_progress {
  int quiet, tty, bar;
  uint32_t frames;         /* N */
  uint32_t frame;          /* index of the frame being rendered */
  double start_ms;         /* of the run */
  double frame_start_ms;
  int line_open;           /* tty: a report is on screen without its newline */
} render_progress;

/* bar: also report rows while a frame renders (references). */
void render_progress_begin(render_progress *p, uint32_t frames, int tty, int quiet, int bar);
void render_progress_frame_start(render_progress *p, uint32_t frame);
/* rows_done of rows of the current frame (the renderer's progress callback). */
void render_progress_rows(render_progress *p, uint32_t rows_done, uint32_t rows);
/* cpu_seconds: the process's CPU time for the frame's rendering (all
 * threads), printed when >= 0: the figure that does not depend on how busy
 * the machine is. */
void render_progress_frame_done(render_progress *p, double render_seconds, double cpu_seconds,
                                uint64_t rays);
/* Ends an open terminal line, before other output and at the end. */
void render_progress_break(render_progress *p);

#endif

/*
 * report.h — the HTML report of `hush eval`. hush__report_write() reads what
 * `hush eval` wrote into a report directory (eval.json, metrics.csv,
 * timings.csv, summary.md, status.csv and frames/<filter>/frame_NNNN.exr)
 * and writes REPORT_DIR/report.html with its pictures in REPORT_DIR/img/:
 * side-by-side images (noisy | each filter | reference) with zoomed insets,
 * error heat maps, per-frame metric plots as SVG, the summary and timing
 * tables, failed filters with their message, and, when ffmpeg is on PATH, a
 * side-by-side video of the whole sequence (REPORT_DIR/video.mp4).
 * Every file is written atomically; nothing is printed.
 */
#ifndef HUSH_EVAL_REPORT_H
#define HUSH_EVAL_REPORT_H

#include "hush.h"

#include <stdint.h>

typedef struct hush_report_options {
  const uint32_t *frames; /* frames to show side by side (sequence frame numbers) */
  uint32_t frame_count;   /* 0 = first, middle and last */
  float exposure;         /* stops, for every picture */
  hush_tonemap tonemap;
  int video;              /* 1: try ffmpeg */
} hush_report_options;

/* Writes REPORT_DIR/report.html (and img/, video.mp4). Errors name the file
 * (and line) that was missing or malformed and are reported on device. */
hush_status hush__report_write(hush_device device, const char *report_dir,
                               const hush_report_options *opt);

#endif

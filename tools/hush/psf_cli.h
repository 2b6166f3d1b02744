/*
 * psf_cli.h — the command-line side of hashed path-space filtering
 * (src/psf/, docs/psf.md), shared by `hush render --psf` and `hush eval`:
 * the --psf-* options, the renderer set-up from them, and the per-frame
 * statistics line and CSV row (the paper's Figure 7 quantities).
 */
#ifndef HUSH_TOOLS_PSF_CLI_H
#define HUSH_TOOLS_PSF_CLI_H

#include "cli.h"

#include "psf/psf_render.h"

#define PSF_CLI_MAX_SETS 32

typedef struct psf_cli {
  int on;                  /* --psf */
  const char *sets[PSF_CLI_MAX_SETS]; /* "KEY=VALUE" */
  int set_count;
  hush_psf_renderer *renderer; /* after psf_cli_open; owned */
} psf_cli;

/* Consumes a --psf* option at arg; returns 1 if it was one. */
int psf_cli_option(cli_args *a, const char *arg, psf_cli *o);

/* Adds a KEY=VALUE setting (as --psf-set); usage error when full. */
void psf_cli_add_set(const char *cmd, psf_cli *o, const char *key_value);

/* Makes o->renderer for frames of width x height at spp and applies the
 * settings. Prints errors; returns 0 or CLI_EXIT_RUNTIME. */
int psf_cli_open(psf_cli *o, const char *cmd, hush_device device, uint32_t width,
                 uint32_t height, uint32_t spp);
void psf_cli_close(psf_cli *o);

/* The CSV header and the row of the frame just filtered. */
void psf_cli_csv_header(FILE *f);
void psf_cli_csv_row(FILE *f, const psf_cli *o, uint32_t frame, const hush_psf_timings *t);
/* One line for stderr: cells, occupancy, collisions, fallbacks, evictions, ms. */
void psf_cli_stats_line(const psf_cli *o, const hush_psf_timings *t, char *buf, size_t size);

#endif

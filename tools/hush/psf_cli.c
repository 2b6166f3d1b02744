/*
 * psf_cli.c — --psf options, renderer set-up and statistics output for
 * `hush render` and `hush eval` (see psf_cli.h).
 */
#include "psf_cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void psf_cli_add_set(const char *cmd, psf_cli *o, const char *key_value) {
  if (!strchr(key_value, '=') || key_value[0] == '=')
    cli_usage_error(cmd, "psf setting '%s' is not KEY=VALUE", key_value);
  if (o->set_count == PSF_CLI_MAX_SETS)
    cli_usage_error(cmd, "more than %d psf settings", PSF_CLI_MAX_SETS);
  o->sets[o->set_count++] = key_value;
}

/* --psf-scale 4 is --psf-set scale=4: the text lives in a small static pool
 * (the options outlive parsing). */
static void add_named(const char *cmd, psf_cli *o, const char *key, const char *value) {
  static char pool[PSF_CLI_MAX_SETS][96];
  static int used = 0;
  if (used == PSF_CLI_MAX_SETS) cli_usage_error(cmd, "too many psf options");
  if ((size_t)snprintf(pool[used], sizeof pool[used], "%s=%s", key, value) >= sizeof pool[used])
    cli_usage_error(cmd, "--psf-%s: value too long", key);
  psf_cli_add_set(cmd, o, pool[used++]);
}

int psf_cli_option(cli_args *a, const char *arg, psf_cli *o) {
  static const struct {
    const char *flag, *key;
  } named[] = {{"--psf-scale", "scale"},
               {"--psf-vertex", "vertex"},
               {"--psf-table-size", "table_size"},
               {"--psf-jitter", "jitter"},
               {"--psf-probes", "probes"},
               {"--psf-max-samples", "max_samples"}};
  const char *v;
  if (cli_switch(a, arg, "--psf")) {
    o->on = 1;
    return 1;
  }
  if (cli_option(a, arg, "--psf-set", &v)) {
    psf_cli_add_set(a->cmd, o, v);
    o->on = 1;
    return 1;
  }
  for (size_t k = 0; k < sizeof named / sizeof named[0]; k++)
    if (cli_option(a, arg, named[k].flag, &v)) {
      add_named(a->cmd, o, named[k].key, v);
      o->on = 1;
      return 1;
    }
  return 0;
}

int psf_cli_open(psf_cli *o, const char *cmd, hush_device device, uint32_t width,
                 uint32_t height, uint32_t spp) {
  hush_status st = hush__psf_renderer_new(device, width, height, spp, 1, &o->renderer);
  if (st != HUSH_OK) return cli_device_error(cmd, device, st, "psf");
  for (int i = 0; i < o->set_count; i++) {
    const char *eq = strchr(o->sets[i], '=');
    char key[64];
    const size_t len = (size_t)(eq - o->sets[i]);
    if (len >= sizeof key) return cli_error(cmd, "psf setting '%s': name too long", o->sets[i]);
    memcpy(key, o->sets[i], len);
    key[len] = '\0';
    st = hush__psf_renderer_set(o->renderer, key, eq + 1);
    if (st != HUSH_OK) return cli_device_error(cmd, device, st, o->sets[i]);
  }
  return 0;
}

void psf_cli_close(psf_cli *o) {
  hush__psf_renderer_free(o->renderer);
  o->renderer = NULL;
}

void psf_cli_csv_header(FILE *f) {
  fputs("frame,vertices,collisions,failed,cells_used,cells_occupied,evictions,table_size,"
        "occupancy,add_ms,resolve_ms,lookup_ms,filter_ms,cpu_ms\n",
        f);
}

void psf_cli_csv_row(FILE *f, const psf_cli *o, uint32_t frame, const hush_psf_timings *t) {
  hush_psf_stats s;
  hush_psf_get_stats(hush__psf_renderer_psf(o->renderer), &s);
  fprintf(f, "%u,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%.6f,%.3f,%.3f,%.3f,%.3f,%.3f\n", frame,
          (unsigned long long)s.vertices, (unsigned long long)s.collisions,
          (unsigned long long)s.failed, (unsigned long long)s.cells_used,
          (unsigned long long)s.cells_occupied, (unsigned long long)s.evictions,
          (unsigned long long)s.table_size, s.occupancy, t->add, t->resolve, t->lookup,
          t->add + t->resolve + t->lookup, t->cpu);
}

void psf_cli_stats_line(const psf_cli *o, const hush_psf_timings *t, char *buf, size_t size) {
  hush_psf_stats s;
  hush_psf_get_stats(hush__psf_renderer_psf(o->renderer), &s);
  const double nv = s.vertices ? (double)s.vertices : 1.0;
  snprintf(buf, size,
           "psf: %llu vertices in %llu cells, occupancy %.1f%%, collisions %.1f%%, no cell "
           "%.2f%%, evictions %llu, %.2f ms (add %.2f, resolve %.2f, lookup %.2f; cpu %.2f)",
           (unsigned long long)s.vertices, (unsigned long long)s.cells_used, 100.0 * s.occupancy,
           100.0 * (double)s.collisions / nv, 100.0 * (double)s.failed / nv,
           (unsigned long long)s.evictions, t->add + t->resolve + t->lookup, t->add, t->resolve,
           t->lookup, t->cpu);
}

/*
 * cmd_synth.c — `hush synth`: writes a synthetic noisy sequence (frames with
 * "color", its noise-free expectation "ref" and the guide layers, plus
 * cameras.json) made by src/eval/synthetic.c, for trying filters without a
 * renderer.
 */
#include "cli.h"

#include "eval/synthetic.h"

#include <stdio.h>
#include <string.h>

static const char *const help_text =
    "usage: hush synth --out DIR [options]\n"
    "\n"
    "Writes a deterministic synthetic sequence to DIR (created if missing):\n"
    "frame_NNNN.exr with the layers color (noisy), ref (its noise-free\n"
    "expectation), albedo, normal, position, depth, motion and id, and\n"
    "cameras.json. The scene is a checkered ground plane and four spheres\n"
    "under a sun with soft shadows; the same options always give the same\n"
    "files.\n"
    "\n"
    "options:\n"
    "  --out DIR            output directory (required)\n"
    "  --size WxH           frame size in pixels (default 320x180)\n"
    "  --frames N           number of frames, 1..100000 (default 16)\n"
    "  --seed S             noise seed, 0..4294967295 (default 1)\n"
    "  --noise X            noise strength, 0 (color = ref) .. 1 (default 1)\n"
    "  --camera MOVE        static, orbit or dolly (default orbit)\n"
    "  --no-moving-object   keep every sphere still (default: one moves)\n"
    "  --half               write half-float EXRs (default float)\n"
    "  --threads N          worker threads, 0 = one per core (default 0)\n"
    "  --quiet              print nothing on success\n"
    "  -h, --help           show this help\n";

static int parse_camera(const char *cmd, const char *text) {
  if (strcmp(text, "static") == 0) return HUSH_SYNTH_STATIC;
  if (strcmp(text, "orbit") == 0) return HUSH_SYNTH_ORBIT;
  if (strcmp(text, "dolly") == 0) return HUSH_SYNTH_DOLLY;
  cli_usage_error(cmd, "--camera: unknown move '%s' (one of: static, orbit, dolly)", text);
}

int cmd_synth(int argc, char **argv) {
  cli_args a;
  cli_args_init(&a, "synth", argc, argv);
  hush_synth_params p;
  hush__synth_defaults(&p);
  const char *arg, *v, *out = NULL;
  uint32_t threads = 0;
  int quiet = 0;
  while (cli_next(&a, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      return 0;
    } else if (cli_option(&a, arg, "--out", &v)) {
      out = v;
    } else if (cli_option(&a, arg, "--size", &v)) {
      cli_parse_size(a.cmd, "--size", v, &p.width, &p.height);
    } else if (cli_option(&a, arg, "--frames", &v)) {
      p.frames = cli_parse_uint(a.cmd, "--frames", v, 1, 100000);
    } else if (cli_option(&a, arg, "--seed", &v)) {
      p.seed = cli_parse_uint(a.cmd, "--seed", v, 0, UINT32_MAX);
    } else if (cli_option(&a, arg, "--noise", &v)) {
      p.noise = cli_parse_float(a.cmd, "--noise", v, 0.0f, 1.0f);
    } else if (cli_option(&a, arg, "--camera", &v)) {
      p.camera_move = parse_camera(a.cmd, v);
    } else if (cli_switch(&a, arg, "--no-moving-object")) {
      p.moving_object = 0;
    } else if (cli_switch(&a, arg, "--half")) {
      p.exr_type = HUSH_EXR_HALF;
    } else if (cli_option(&a, arg, "--threads", &v)) {
      threads = cli_parse_uint(a.cmd, "--threads", v, 0, 1024);
    } else if (cli_switch(&a, arg, "--quiet")) {
      quiet = 1;
    } else if (cli_is_positional(&a, arg)) {
      cli_usage_error(a.cmd, "unexpected argument '%s' (the output goes to --out DIR)", arg);
    } else {
      cli_unknown_option(&a, arg);
    }
  }
  if (!out) cli_usage_error(a.cmd, "--out DIR is required (see hush synth --help)");

  hush_device device = cli_device_new(a.cmd, threads);
  if (!device) return CLI_EXIT_RUNTIME;
  const hush_status st = hush__synth_write_sequence(device, &p, out);
  int rc = 0;
  if (st != HUSH_OK)
    rc = cli_device_error(a.cmd, device, st, NULL);
  else if (!quiet)
    fprintf(stderr, "wrote %u frames of %ux%u to %s\n", p.frames, p.width, p.height, out);
  hush_device_release(device);
  return rc;
}

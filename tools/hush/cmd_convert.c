/*
 * cmd_convert.c — `hush convert IN OUT`: converts one image between EXR
 * (every layer of a frame), PNG (8-bit sRGB, one layer) and PFM (float, one
 * layer), choosing the reader and the writer by file extension.
 */
#include "cli.h"

#include <stdio.h>
#include <string.h>

static const char *const help_text =
    "usage: hush convert IN OUT [options]\n"
    "\n"
    "Converts an image; the formats come from the extensions (.exr, .png,\n"
    ".pfm, any case):\n"
    "  EXR -> PNG   one layer, radiance * 2^exposure, tone mapped, sRGB, 8 bits\n"
    "  EXR -> PFM   one layer of 1 or 3 channels (the first 3 of 4), linear\n"
    "  EXR -> EXR   every layer (or only --layer), e.g. to change --half\n"
    "  PNG -> EXR   decoded from sRGB to linear, stored as one layer\n"
    "  PFM -> EXR   stored as one layer\n"
    "  PNG, PFM -> PNG, PFM also work, through the same steps.\n"
    "\n"
    "options:\n"
    "  --layer NAME       the layer written to PNG/PFM, or kept from EXR to EXR;\n"
    "                     for PNG/PFM input, the name of the layer made\n"
    "                     (default color)\n"
    "  --exposure E       PNG output: scale radiance by 2^E, -64..64 (default 0)\n"
    "  --tonemap T        PNG output: clamp, reinhard or aces (default clamp)\n"
    "  --half             EXR output: half floats (default float)\n"
    "  -h, --help         show this help\n";

typedef enum file_kind { KIND_EXR, KIND_PNG, KIND_PFM } file_kind;

static file_kind kind_of(const char *cmd, const char *path) {
  char ext[16];
  cli_extension(path, ext, sizeof ext);
  if (strcmp(ext, "exr") == 0) return KIND_EXR;
  if (strcmp(ext, "png") == 0) return KIND_PNG;
  if (strcmp(ext, "pfm") == 0) return KIND_PFM;
  if (!ext[0]) cli_usage_error(cmd, "'%s' has no extension (known: .exr, .png, .pfm)", path);
  cli_usage_error(cmd, "unknown extension '.%s' of '%s' (known: .exr, .png, .pfm)", ext, path);
}

static hush_status read_input(hush_device device, file_kind kind, const char *path,
                              const char *layer, hush_frame *frame) {
  switch (kind) {
  case KIND_EXR: return hush_frame_read_exr(device, path, frame);
  case KIND_PNG: return hush_frame_read_png(device, path, layer, frame);
  case KIND_PFM: return hush_frame_read_pfm(device, path, layer, frame);
  }
  return HUSH_ERROR_UNSUPPORTED;
}

static int missing_layer(const char *cmd, hush_frame frame, const char *in, const char *layer) {
  char names[512] = "";
  for (uint32_t i = 0; i < hush_frame_layer_count(frame); i++) {
    const size_t len = strlen(names);
    snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "", hush_frame_layer_name(frame, i));
  }
  return cli_error(cmd, "%s has no layer '%s' (it has: %s); choose one with --layer", in, layer,
                   names);
}

/* A new frame holding a copy of one layer of src. */
static hush_status copy_layer(hush_device device, hush_frame src, const char *layer,
                              hush_frame *out) {
  hush_image_view from, to;
  hush_status st = hush_frame_get_layer(src, layer, &from);
  if (st != HUSH_OK) return st;
  const int channels = hush_format_channels(from.format);
  hush_frame f = hush_frame_new(device, from.width, from.height);
  if (!f) return HUSH_ERROR_OUT_OF_MEMORY;
  st = hush_frame_add_layer(f, layer, channels, &to);
  if (st != HUSH_OK) {
    hush_frame_release(f);
    return st;
  }
  const size_t bytes = hush_format_pixel_size(from.format) * from.width;
  for (uint32_t y = 0; y < from.height; y++) {
    const size_t rs_from = from.row_stride ? from.row_stride : bytes;
    const size_t rs_to = to.row_stride ? to.row_stride : bytes;
    memcpy((char *)to.data + to.byte_offset + y * rs_to,
           (const char *)from.data + from.byte_offset + y * rs_from, bytes);
  }
  *out = f;
  return HUSH_OK;
}

typedef struct convert_options {
  const char *in, *out, *layer;
  int layer_given;
  float exposure;
  hush_tonemap tonemap;
  hush_exr_type exr_type;
} convert_options;

static int write_output(const char *cmd, hush_device device, hush_frame frame, file_kind in_kind,
                        file_kind out_kind, const convert_options *o) {
  hush_status st;
  if (out_kind == KIND_EXR) {
    hush_frame keep = NULL;
    if (in_kind == KIND_EXR && o->layer_given) {
      if (hush_frame_get_layer(frame, o->layer, NULL) != HUSH_OK)
        return missing_layer(cmd, frame, o->in, o->layer);
      st = copy_layer(device, frame, o->layer, &keep);
      if (st != HUSH_OK) return cli_device_error(cmd, device, st, o->in);
    }
    st = hush_frame_write_exr(keep ? keep : frame, o->out, o->exr_type);
    hush_frame_release(keep);
    return st == HUSH_OK ? 0 : cli_device_error(cmd, device, st, NULL);
  }

  hush_image_view view;
  if (hush_frame_get_layer(frame, o->layer, &view) != HUSH_OK)
    return missing_layer(cmd, frame, o->in, o->layer);
  const int channels = hush_format_channels(view.format);
  if (out_kind == KIND_PNG) {
    if (channels == 2)
      return cli_error(cmd, "layer '%s' has 2 channels; PNG needs 1, 3 or 4", o->layer);
    st = hush_image_write_png(device, &view, o->out, o->exposure, o->tonemap);
    return st == HUSH_OK ? 0 : cli_device_error(cmd, device, st, NULL);
  }
  if (channels == 2)
    return cli_error(cmd, "layer '%s' has 2 channels; PFM holds 1 or 3", o->layer);
  if (channels == 4) {
    /* the first three of four: same pixels, a 3-channel format, the 4-wide stride */
    view.pixel_stride = hush_format_pixel_size(view.format);
    view.format = HUSH_FORMAT_FLOAT3;
  }
  st = hush_image_write_pfm(device, &view, o->out);
  return st == HUSH_OK ? 0 : cli_device_error(cmd, device, st, NULL);
}

int cmd_convert(int argc, char **argv) {
  cli_args a;
  cli_args_init(&a, "convert", argc, argv);
  convert_options o = {NULL, NULL, "color", 0, 0.0f, HUSH_TONEMAP_CLAMP, HUSH_EXR_FLOAT};
  int png_only = 0, exr_only = 0;
  const char *arg, *v;
  while (cli_next(&a, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      return 0;
    } else if (cli_option(&a, arg, "--layer", &v)) {
      o.layer = v;
      o.layer_given = 1;
    } else if (cli_option(&a, arg, "--exposure", &v)) {
      o.exposure = cli_parse_float(a.cmd, "--exposure", v, -64.0f, 64.0f);
      png_only = 1;
    } else if (cli_option(&a, arg, "--tonemap", &v)) {
      o.tonemap = cli_parse_tonemap(a.cmd, "--tonemap", v);
      png_only = 1;
    } else if (cli_switch(&a, arg, "--half")) {
      o.exr_type = HUSH_EXR_HALF;
      exr_only = 1;
    } else if (cli_is_positional(&a, arg) && !o.in) {
      o.in = arg;
    } else if (cli_is_positional(&a, arg) && !o.out) {
      o.out = arg;
    } else if (cli_is_positional(&a, arg)) {
      cli_usage_error(a.cmd, "unexpected argument '%s' (expected IN OUT)", arg);
    } else {
      cli_unknown_option(&a, arg);
    }
  }
  if (!o.in || !o.out) cli_usage_error(a.cmd, "expected IN OUT (see hush convert --help)");
  const file_kind in_kind = kind_of(a.cmd, o.in);
  const file_kind out_kind = kind_of(a.cmd, o.out);
  if (png_only && out_kind != KIND_PNG)
    cli_usage_error(a.cmd, "--exposure and --tonemap apply to PNG output only");
  if (exr_only && out_kind != KIND_EXR) cli_usage_error(a.cmd, "--half applies to EXR output only");

  hush_device device = cli_device_new(a.cmd, 1);
  if (!device) return CLI_EXIT_RUNTIME;
  hush_frame frame = NULL;
  const hush_status st = read_input(device, in_kind, o.in, o.layer, &frame);
  int rc;
  if (st != HUSH_OK)
    rc = cli_device_error(a.cmd, device, st, NULL);
  else
    rc = write_output(a.cmd, device, frame, in_kind, out_kind, &o);
  hush_frame_release(frame);
  hush_device_release(device);
  return rc;
}

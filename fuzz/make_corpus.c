/*
 * make_corpus.c — writes the seed corpus of fuzz_exr: small valid EXRs that
 * reach the reader's main paths. Half and float scanline files come from
 * hush itself; a tiled, PIZ-compressed file with half and uint channels is
 * written with OpenEXR directly, since hush writes only scanlines.
 *   usage: fuzz_exr_make_corpus DIR
 */
#include "core/half.h"
#include "hush.h"

#include <openexr.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int write_frame(hush_device device, const char *dir, const char *name, uint32_t w,
                       uint32_t h, const char *const *layers, const int *channels, int n,
                       hush_exr_type type) {
  hush_frame frame = hush_frame_new(device, w, h);
  if (!frame) return 0;
  int ok = 1;
  for (int l = 0; l < n && ok; l++) {
    hush_image_view view;
    ok = hush_frame_add_layer(frame, layers[l], channels[l], &view) == HUSH_OK;
    float *p = ok ? view.data : NULL;
    for (size_t i = 0; ok && i < (size_t)w * h * (size_t)channels[l]; i++)
      p[i] = (float)((i * 37 + (size_t)l * 11) % 64) * 0.125f;
  }
  char path[4096];
  snprintf(path, sizeof path, "%s/%s", dir, name);
  ok = ok && hush_frame_write_exr(frame, path, type) == HUSH_OK;
  hush_frame_release(frame);
  return ok;
}

static void silent(exr_const_context_t ctxt, exr_result_t code, const char *msg) {
  (void)ctxt;
  (void)code;
  (void)msg;
}

/* A 20x12 tiled (8x8 tiles), PIZ-compressed file: half B, G, R and uint id. */
static int write_tiled(const char *dir) {
  enum { W = 20, H = 12, T = 8, N = 4 };
  static const char *const names[N] = {"B", "G", "R", "id"};
  const exr_pixel_type_t types[N] = {EXR_PIXEL_HALF, EXR_PIXEL_HALF, EXR_PIXEL_HALF,
                                     EXR_PIXEL_UINT};
  static uint8_t planes[N][W * H * 4];
  for (int c = 0; c < N; c++)
    for (int i = 0; i < W * H; i++) {
      if (types[c] == EXR_PIXEL_HALF) {
        const uint16_t v = hush__float_to_half((float)((i + c) % 16) * 0.25f);
        memcpy(&planes[c][2 * i], &v, 2);
      } else {
        const uint32_t v = (uint32_t)(i / 7);
        memcpy(&planes[c][4 * i], &v, 4);
      }
    }
  char path[4096];
  snprintf(path, sizeof path, "%s/tiled_piz.exr", dir);
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.error_handler_fn = silent;
  exr_context_t ctx = NULL;
  int part = 0;
  if (exr_start_write(&ctx, path, EXR_WRITE_FILE_DIRECTLY, &init) != EXR_ERR_SUCCESS) return 0;
  int ok = exr_add_part(ctx, NULL, EXR_STORAGE_TILED, &part) == EXR_ERR_SUCCESS &&
           exr_initialize_required_attr_simple(ctx, part, W, H, EXR_COMPRESSION_PIZ) ==
               EXR_ERR_SUCCESS &&
           exr_set_tile_descriptor(ctx, part, T, T, EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN) ==
               EXR_ERR_SUCCESS;
  for (int c = 0; c < N && ok; c++)
    ok = exr_add_channel(ctx, part, names[c], types[c], EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1) ==
         EXR_ERR_SUCCESS;
  ok = ok && exr_write_header(ctx) == EXR_ERR_SUCCESS;
  exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
  int first = 1;
  for (int ty = 0; ok && ty * T < H; ty++)
    for (int tx = 0; ok && tx * T < W; tx++) {
      exr_chunk_info_t ci;
      ok = exr_write_tile_chunk_info(ctx, part, tx, ty, 0, 0, &ci) == EXR_ERR_SUCCESS;
      ok = ok && (first ? exr_encoding_initialize(ctx, part, &ci, &enc)
                        : exr_encoding_update(ctx, part, &ci, &enc)) == EXR_ERR_SUCCESS;
      for (int c = 0; ok && c < enc.channel_count; c++) {
        int k = 0;
        while (k < N && strcmp(names[k], enc.channels[c].channel_name) != 0) k++;
        ok = k < N;
        if (!ok) break;
        const int bpe = types[k] == EXR_PIXEL_HALF ? 2 : 4;
        enc.channels[c].encode_from_ptr =
            &planes[k][((size_t)ty * T * W + (size_t)tx * T) * (size_t)bpe];
        enc.channels[c].user_pixel_stride = bpe;
        enc.channels[c].user_line_stride = W * bpe;
        enc.channels[c].user_bytes_per_element = (int16_t)bpe;
        enc.channels[c].user_data_type = (uint16_t)types[k];
      }
      if (ok && first)
        ok = exr_encoding_choose_default_routines(ctx, part, &enc) == EXR_ERR_SUCCESS;
      ok = ok && exr_encoding_run(ctx, part, &enc) == EXR_ERR_SUCCESS;
      first = 0;
    }
  if (!first) exr_encoding_destroy(ctx, &enc);
  return exr_finish(&ctx) == EXR_ERR_SUCCESS && ok;
}

int main(int argc, char **argv) {
  if (argc != 2) {
    fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 2;
  }
  const char *dir = argv[1];
  hush_device device = hush_device_new("threads=1");
  if (!device) return 1;
  static const char *const color[] = {"color"};
  static const int rgb[] = {3}, rgba[] = {4};
  static const char *const aovs[] = {"color", "albedo", "normal", "depth", "motion", "id"};
  static const int aov_channels[] = {3, 3, 3, 1, 2, 1};
  int ok =
      write_frame(device, dir, "half_rgb.exr", 8, 8, color, rgb, 1, HUSH_EXR_HALF) &&
      write_frame(device, dir, "float_layers.exr", 7, 5, aovs, aov_channels, 6, HUSH_EXR_FLOAT) &&
      write_frame(device, dir, "half_rgba_tall.exr", 3, 40, color, rgba, 1, HUSH_EXR_HALF) &&
      write_tiled(dir);
  const char *message = "";
  if (!ok && hush_device_get_error(device, &message) == HUSH_OK) message = "OpenEXR failed";
  hush_device_release(device);
  if (!ok) {
    fprintf(stderr, "%s: cannot write the corpus: %s\n", argv[0], message);
    return 1;
  }
  return 0;
}

/*
 * denoise_frame.c — the smallest complete use of libhush: read one EXR frame,
 * run a filter on it, write the result as EXR and PNG. Public API only.
 *
 *   denoise_frame IN.exr OUT.exr OUT.png [FILTER]     (FILTER: accumulate)
 *
 * A temporal filter run on a single frame has no history: feed it a
 * sequence (see `hush denoise`) to see it converge.
 */
#include <hush.h>

#include <stdio.h>

/* Prints the device's error message and returns 1, for `return fail(...)`. */
static int fail(hush_device device, const char *what) {
  const char *message = "";
  const hush_status status = hush_device_get_error(device, &message);
  fprintf(stderr, "denoise_frame: %s: %s (%s)\n", what, message, hush_status_name(status));
  return 1;
}

/* Binds every input image of the filter that the frame has a layer for,
 * and the output to a new layer of the same size. */
static int bind(hush_device device, hush_filter filter, hush_frame in, hush_frame out) {
  const hush_filter_class_info *cls = hush_filter_get_class(filter);
  for (uint32_t i = 0; i < cls->image_count; i++) {
    const hush_image_info *image = &cls->images[i];
    hush_image_view view;
    if (image->role == HUSH_IMAGE_OUTPUT) {
      if (!image->required) continue;
      if (hush_frame_add_layer(out, "color", image->channels, &view) != HUSH_OK)
        return fail(device, "output layer");
    } else if (hush_frame_get_layer(in, image->name, &view) != HUSH_OK) {
      if (!image->required) continue;
      fprintf(stderr, "denoise_frame: the frame has no '%s' layer, which '%s' requires\n",
              image->name, cls->name);
      return 1;
    }
    if (hush_filter_set_image(filter, image->name, &view) != HUSH_OK)
      return fail(device, image->name);
  }
  return 0;
}

int main(int argc, char **argv) {
  if (argc < 4 || argc > 5) {
    fprintf(stderr, "usage: denoise_frame IN.exr OUT.exr OUT.png [FILTER]\n");
    return 2;
  }
  const char *filter_name = argc == 5 ? argv[4] : "accumulate";

  hush_device device = hush_device_new(NULL);
  if (!device) return fail(NULL, "device");
  hush_frame in = NULL, out = NULL;
  hush_filter filter = NULL;
  hush_frame_info info;
  hush_image_view result;
  int rc = 1;

  if (hush_frame_read_exr(device, argv[1], &in) != HUSH_OK) {
    rc = fail(device, argv[1]);
    goto done;
  }
  out = hush_frame_new(device, hush_frame_width(in), hush_frame_height(in));
  filter = hush_filter_new(device, filter_name);
  if (!out || !filter) {
    rc = fail(device, filter_name);
    goto done;
  }
  if (bind(device, filter, in, out) != 0) goto done;
  if (hush_filter_commit(filter) != HUSH_OK) {
    rc = fail(device, "commit");
    goto done;
  }
  /* One frame: identity matrices and no history are right. A renderer would
   * fill in its cameras here (see hush.h for the conventions). */
  hush_frame_info_init(&info);
  info.history = HUSH_HISTORY_RESET;
  if (hush_filter_execute(filter, &info) != HUSH_OK) {
    rc = fail(device, "execute");
    goto done;
  }

  if (hush_frame_write_exr(out, argv[2], HUSH_EXR_HALF) != HUSH_OK) {
    rc = fail(device, argv[2]);
    goto done;
  }
  if (hush_frame_get_layer(out, "color", &result) != HUSH_OK ||
      hush_image_write_png(device, &result, argv[3], 0.0f, HUSH_TONEMAP_ACES) != HUSH_OK) {
    rc = fail(device, argv[3]);
    goto done;
  }
  printf("%s: %ux%u through '%s' -> %s, %s\n", argv[1], hush_frame_width(in),
         hush_frame_height(in), filter_name, argv[2], argv[3]);
  rc = 0;

done:
  hush_filter_release(filter);
  hush_frame_release(out);
  hush_frame_release(in);
  hush_device_release(device);
  return rc;
}

/*
 * scene_frames.c — renders frames of a scene into memory through the
 * library renderer, with the camera set-up of cmd_render.c (see
 * scene_frames.h), so `hush eval --scene` and `hush bench --scene` see the
 * frames `hush render` would write.
 */
#include "scene_frames.h"

#include "cli.h"

#include "core/timer.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int fail(scene_frames *s, hush_status st, const char *context) {
  return cli_device_error(s->cmd, s->device, st, context);
}

static int load_scene(scene_frames *s, const char *name) {
  hush_status st;
  if (strncmp(name, "builtin:", 8) == 0)
    st = hush__scene_builtin(s->device, name + 8, &s->scene);
  else
    st = hush__scene_load(s->device, name, &s->scene);
  if (st != HUSH_OK) return fail(s, st, name);
  s->have_scene = 1;
  st = hush__scene_commit(s->device, &s->scene);
  if (st != HUSH_OK) return fail(s, st, name);
  st = hush__lights_init(s->device, &s->lights, &s->scene);
  if (st != HUSH_OK) return fail(s, st, name);
  s->have_lights = 1;
  return 0;
}

/* The camera move, as `hush render --path` chooses it. */
static int choose_move(scene_frames *s, const char *p) {
  s->path = s->scene.path.frame_count ? &s->scene.path : NULL;
  if (!p) {
    s->move = s->path ? HUSH_MOVE_PATH : HUSH_MOVE_ORBIT;
  } else if (strcmp(p, "static") == 0) {
    s->move = HUSH_MOVE_STATIC;
  } else if (strcmp(p, "orbit") == 0) {
    s->move = HUSH_MOVE_ORBIT;
  } else if (strcmp(p, "dolly") == 0) {
    s->move = HUSH_MOVE_DOLLY;
  } else if (strcmp(p, "path") == 0) {
    if (!s->path)
      return cli_error(s->cmd, "--path path: scene '%s' has no camera path", s->scene.name);
    s->move = HUSH_MOVE_PATH;
  } else {
    const hush_status st = hush__camera_path_load(s->device, p, &s->file_path);
    if (st != HUSH_OK) return fail(s, st, p);
    s->path = &s->file_path;
    s->move = HUSH_MOVE_PATH;
  }
  return 0;
}

static int moves_anything(const hush_scene *sc) {
  for (uint32_t i = 0; i < sc->object_count; i++)
    if (sc->objects[i].motion.animated) return 1;
  for (uint32_t i = 0; i < sc->sphere_count; i++) {
    const float *v = sc->spheres[i].velocity;
    if (v[0] != 0.0f || v[1] != 0.0f || v[2] != 0.0f) return 1;
  }
  return 0;
}

int scene_frames_open(scene_frames *s, const char *cmd, hush_device device, const char *scene,
                      const char *path, uint32_t width, uint32_t height, uint32_t frames) {
  memset(s, 0, sizeof *s);
  s->cmd = cmd;
  s->device = device;
  int rc = load_scene(s, scene);
  if (!rc) rc = choose_move(s, path);
  if (rc) return rc;
  s->width = width ? width : s->scene.width ? s->scene.width : 640;
  s->height = height ? height : s->scene.height ? s->scene.height : 360;
  s->frames = frames ? frames : s->move == HUSH_MOVE_PATH ? s->path->frame_count : 16;
  if (s->move == HUSH_MOVE_PATH && s->frames > s->path->frame_count)
    return cli_error(cmd, "--frames %u: the camera path has %u frames", s->frames,
                     s->path->frame_count);
  if (!hush__lights_any(&s->lights))
    fprintf(stderr, "hush %s: warning: scene '%s' has no light: the frames render black\n", cmd,
            s->scene.name);
  s->motion = moves_anything(&s->scene) ? HUSH_MOTION_VECTORS : HUSH_MOTION_CAMERA;
  return 0;
}

static void rows_progress(void *user, uint32_t done, uint32_t rows) {
  render_progress_rows(user, done, rows);
}

int scene_frames_render(scene_frames *s, uint32_t i, const hush_render_params *params,
                        int threads, render_progress *progress, hush_frame *out,
                        hush_camera *camera) {
  *out = NULL;
  hush_render_params p = *params;
  p.width = s->width;
  p.height = s->height;
  p.threads = threads;
  hush_status st = hush__scene_set_frame(s->device, &s->scene, i);
  if (st != HUSH_OK) return fail(s, st, "set frame");
  hush__lights_set_frame(&s->lights, i);
  hush_render_camera cam, prev;
  hush_camera_move_setup moves;
  /* one projection for the whole sequence, from frame 0's eye, as hush render */
  hush__camera_move_init(&moves, &s->scene, s->move, s->path, s->width, s->height, p.jitter, 0);
  int have_prev;
  if (!hush__camera_move_frame(&moves, i, &cam, &prev, &have_prev))
    return cli_error(s->cmd, "frame %u: degenerate camera (eye on target, or up along the view)",
                     i);
  if (s->psf) hush__psf_renderer_hook(s->psf, &p);
  hush_render_ctx ctx;
  hush__render_ctx_init(&ctx, &s->scene, &s->lights, &p, &cam, have_prev ? &prev : NULL, i);
  if (s->psf) {
    st = hush__psf_renderer_begin(s->psf, &ctx, i == 0 ? HUSH_HISTORY_RESET : HUSH_HISTORY_CONTINUE);
    if (st != HUSH_OK) return fail(s, st, "psf");
  }
  hush_frame frame = hush_frame_new(s->device, s->width, s->height);
  if (!frame) return fail(s, HUSH_ERROR_OUT_OF_MEMORY, "frame");
  if (progress) render_progress_frame_start(progress, i);
  const double t0 = hush__now_ms();
  uint64_t rays = 0;
  st = hush__render_frame(s->device, &ctx, frame, progress ? rows_progress : NULL, progress, &rays);
  if (st == HUSH_OK && s->psf) st = hush__psf_renderer_finish(s->psf, frame, &s->psf_timings);
  if (st != HUSH_OK) {
    hush_frame_release(frame);
    if (progress) render_progress_break(progress);
    return fail(s, st, "render");
  }
  if (progress) render_progress_frame_done(progress, (hush__now_ms() - t0) / 1000.0, -1.0, rays);
  memcpy(camera->world_to_view, cam.world_to_view, sizeof camera->world_to_view);
  memcpy(camera->view_to_clip, cam.view_to_clip, sizeof camera->view_to_clip);
  memcpy(camera->jitter, cam.jitter, sizeof camera->jitter);
  *out = frame;
  return 0;
}

void scene_frames_close(scene_frames *s) {
  free(s->file_path.frames);
  if (s->have_lights) hush__lights_free(&s->lights);
  if (s->have_scene) hush__scene_free(&s->scene);
  memset(s, 0, sizeof *s);
}

/*
 * scene_frames.h — frames of a scene rendered into memory with the library
 * renderer (src/render/), the way `hush render` makes them: the same camera
 * moves (the scene's path, a camera-path.json, static, orbit, dolly), one
 * projection for the sequence from frame 0's eye, Halton jitter per frame,
 * previous cameras for the motion vectors. `hush eval --scene` renders its
 * sequence and references with it, `hush bench --scene` its frames.
 */
#ifndef HUSH_TOOLS_SCENE_FRAMES_H
#define HUSH_TOOLS_SCENE_FRAMES_H

#include "render_progress.h"

#include "io/sequence.h"
#include "psf/psf_render.h"
#include "render/camera.h"
#include "render/lights.h"
#include "render/render.h"
#include "render/scene.h"

typedef struct scene_frames {
  const char *cmd;          /* for messages */
  hush_device device;
  hush_scene scene;
  int have_scene;
  hush_lights lights;
  int have_lights;
  hush_camera_path file_path; /* a --path FILE.json */
  const hush_camera_path *path;
  hush_camera_move move;
  uint32_t width, height;   /* resolved */
  uint32_t frames;          /* resolved: what the caller asked, or the path's length, or 16 */
  hush_motion_source motion; /* VECTORS when an object or sphere light moves */
  hush_psf_renderer *psf;   /* not NULL: also filter with psf into layer "psf" (not owned) */
  hush_psf_timings psf_timings; /* of the last frame rendered with psf */
} scene_frames;

/*
 * Loads `scene` (a scene.json path or its folder, or builtin:NAME) and
 * resolves the camera move `path` (NULL: the scene's path, else orbit;
 * "path", "static", "orbit", "dolly" or a .json file), the size (0: the
 * scene's resolution, else 640x360) and the frame count (0: the path's
 * length, else 16). Prints errors as "hush <cmd>: ..."; returns 0 or
 * CLI_EXIT_RUNTIME. scene_frames_close() it either way.
 */
int scene_frames_open(scene_frames *s, const char *cmd, hush_device device, const char *scene,
                      const char *path, uint32_t width, uint32_t height, uint32_t frames);

/*
 * Renders animation frame i (0 <= i < s->frames) with params (its size and
 * threads are overwritten) into a new frame *out, owned by the caller, and
 * its camera into *camera. progress may be NULL. Returns 0 or
 * CLI_EXIT_RUNTIME (printed).
 */
int scene_frames_render(scene_frames *s, uint32_t i, const hush_render_params *params,
                        int threads, render_progress *progress, hush_frame *out,
                        hush_camera *camera);

void scene_frames_close(scene_frames *s);

#endif

/*
 * camera.h — the renderer's camera: a pinhole pose per frame (from the
 * scene's camera path, a camera-path.json, or a procedural orbit / dolly
 * around the scene camera's target) turned into the world_to_view and
 * view_to_clip matrices of hush.h, Halton(2,3) subpixel jitter, and primary
 * rays through (x + 0.5 + jx, y + 0.5 + jy). The papers' 1 spp inputs jitter
 * the primary ray for TAA (bmfr-koskela-2019.md §3.1, §3.5); the jitter is
 * kept out of the matrices as hush.h requires.
 */
#ifndef HUSH_RENDER_CAMERA_H
#define HUSH_RENDER_CAMERA_H

#include "hush.h"
#include "core/hmath.h"
#include "render/scene.h"

#include <stdint.h>

typedef enum hush_camera_move {
  HUSH_MOVE_PATH = 0,   /* one pose per frame from a camera path */
  HUSH_MOVE_STATIC = 1, /* the scene's camera, every frame */
  HUSH_MOVE_ORBIT = 2,  /* around the target, about the camera's up axis */
  HUSH_MOVE_DOLLY = 3   /* towards the target and back */
} hush_camera_move;

/* Procedural moves, per frame: orbit HUSH_ORBIT_DEG_PER_FRAME degrees;
 * dolly to HUSH_DOLLY_MIN of the distance and back in HUSH_DOLLY_PERIOD frames. */
#define HUSH_ORBIT_DEG_PER_FRAME 0.5f
#define HUSH_DOLLY_MIN 0.6f
#define HUSH_DOLLY_PERIOD 120u

/* Names of the moves, NULL-terminated, for --list and --path. */
extern const char *const hush__camera_move_names[];

/* A camera set up for one frame. */
typedef struct hush_render_camera {
  uint32_t width, height;
  float world_to_view[16], view_to_clip[16]; /* without jitter */
  float view_to_world[16];
  float jitter[2];         /* pixels, in [-0.5, 0.5) */
  hush_vec3 eye;
  float tan_half_x, tan_half_y; /* half extents of the image plane at view depth 1 */
  float z_near, z_far;
} hush_render_camera;

/* The pose of `frame`: the path's frame (clamped to its last one) for
 * HUSH_MOVE_PATH, else the scene camera moved procedurally. path may be NULL
 * for the procedural moves. *fov_axis_x tells how fov_deg is measured. */
void hush__camera_pose(const hush_scene *scene, hush_camera_move move, const hush_camera_path *path,
                       uint32_t frame, hush_camera_pose *pose, int *fov_axis_x);

/* Near and far planes that enclose the scene seen from eye (they only
 * matter for NDC z: "depth" is linear). */
void hush__camera_clip_range(const hush_scene *scene, hush_vec3 eye, float *z_near, float *z_far);

/* Fills cam from a pose; jitter is Halton(2,3) of the frame when jitter is
 * set, else 0. Returns 0 for a degenerate pose (eye on target, up parallel
 * to the view direction, fov outside (0, 180)). */
int hush__camera_setup(hush_render_camera *cam, const hush_camera_pose *pose, int fov_axis_x,
                       uint32_t width, uint32_t height, float z_near, float z_far, uint32_t frame,
                       int jitter);

/* A camera move over a sequence: one projection (near/far planes from the
 * eye of the sequence's first frame, with margin) for every frame, so that
 * inputs and references rendered separately get identical cameras. */
typedef struct hush_camera_move_setup {
  const hush_scene *scene;
  hush_camera_move move;
  const hush_camera_path *path; /* HUSH_MOVE_PATH; else may be NULL */
  uint32_t width, height;
  int jitter;
  float z_near, z_far;
} hush_camera_move_setup;

/* Fills m for a sequence that starts at first_frame. */
void hush__camera_move_init(hush_camera_move_setup *m, const hush_scene *scene,
                            hush_camera_move move, const hush_camera_path *path, uint32_t width,
                            uint32_t height, int jitter, uint32_t first_frame);

/* The cameras of `frame` and of the frame before it (*have_prev = 0 at frame
 * 0, or when that pose is degenerate). Returns 0 if this frame's pose is
 * degenerate. */
int hush__camera_move_frame(const hush_camera_move_setup *m, uint32_t frame, hush_render_camera *cam,
                            hush_render_camera *prev, int *have_prev);

/* Halton(2,3) point of frame (index frame % 16 + 1) minus 0.5: in (-0.5, 0.5). */
void hush__camera_jitter(uint32_t frame, float jitter[2]);

/* World-space unit direction of the ray through image point (px, py) in
 * pixels (row 0 at the top); the ray starts at cam->eye. */
hush_vec3 hush__camera_ray(const hush_render_camera *cam, float px, float py);

/* Image point (pixels) of a world point (w = 1) or direction (w = 0) with
 * the camera's matrices (no jitter). Returns 0 if it lies behind the camera. */
int hush__camera_project(const hush_render_camera *cam, hush_vec3 p, float w, float *px, float *py);

/* Reads a camera-path.json ({"fov_axis", "resolution", "frames": [{position,
 * target, up, fov_deg}, ...]}). Errors name the file and the field. The
 * caller frees path->frames with free(). */
hush_status hush__camera_path_load(hush_device device, const char *file, hush_camera_path *path);

#endif

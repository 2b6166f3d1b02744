/*
 * camera.c — poses, matrices, jitter and primary rays (see camera.h).
 * Follows the 1 spp set-up of bmfr-koskela-2019.md §3.1 / §6: one primary
 * ray per pixel, jittered per frame for temporal anti-aliasing.
 */
#include "render/camera.h"

#include "core/device.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CAM_PI 3.14159265358979f
#define PATH_MAX_BYTES (64ll << 20)

const char *const hush__camera_move_names[] = {"path", "static", "orbit", "dolly", NULL};

/* ---- poses ---------------------------------------------------------------- */

/* Rodrigues rotation of v about the unit axis k. */
static hush_vec3 rotate_about(hush_vec3 v, hush_vec3 k, float angle) {
  const float c = cosf(angle), s = sinf(angle);
  const hush_vec3 kxv = hush_v3_cross(k, v);
  const float kv = hush_v3_dot(k, v);
  return hush_v3_add(hush_v3_add(hush_v3_scale(v, c), hush_v3_scale(kxv, s)),
                     hush_v3_scale(k, kv * (1.0f - c)));
}

/* 0 -> 1 -> 0 over `period` frames, so long sequences stay in the scene. */
static float triangle_wave(uint32_t frame, uint32_t period) {
  const float t = (float)(frame % period) / (float)period;
  return t < 0.5f ? 2.0f * t : 2.0f - 2.0f * t;
}

void hush__camera_pose(const hush_scene *scene, hush_camera_move move, const hush_camera_path *path,
                       uint32_t frame, hush_camera_pose *pose, int *fov_axis_x) {
  if (move == HUSH_MOVE_PATH && path && path->frame_count > 0) {
    const uint32_t i = frame < path->frame_count ? frame : path->frame_count - 1;
    *pose = path->frames[i];
    *fov_axis_x = path->fov_axis_x;
    return;
  }
  *pose = scene->camera;
  *fov_axis_x = scene->camera_fov_axis_x;
  const hush_vec3 eye = hush_v3(pose->position[0], pose->position[1], pose->position[2]);
  const hush_vec3 target = hush_v3(pose->target[0], pose->target[1], pose->target[2]);
  const hush_vec3 offset = hush_v3_sub(eye, target);
  hush_vec3 moved = offset;
  if (move == HUSH_MOVE_ORBIT) {
    const hush_vec3 up = hush_v3_normalize(hush_v3(pose->up[0], pose->up[1], pose->up[2]));
    const float angle = HUSH_ORBIT_DEG_PER_FRAME * (float)frame * CAM_PI / 180.0f;
    moved = rotate_about(offset, up, angle);
  } else if (move == HUSH_MOVE_DOLLY) {
    const float s = 1.0f - (1.0f - HUSH_DOLLY_MIN) * triangle_wave(frame, HUSH_DOLLY_PERIOD);
    moved = hush_v3_scale(offset, s);
  }
  pose->position[0] = target.x + moved.x;
  pose->position[1] = target.y + moved.y;
  pose->position[2] = target.z + moved.z;
}

void hush__camera_clip_range(const hush_scene *scene, hush_vec3 eye, float *z_near, float *z_far) {
  float lo[3] = {FLT_MAX, FLT_MAX, FLT_MAX}, hi[3] = {-FLT_MAX, -FLT_MAX, -FLT_MAX};
  for (uint32_t i = 0; i < scene->vertex_count; i++)
    for (int k = 0; k < 3; k++) {
      const float v = scene->positions[3 * i + k];
      if (!isfinite(v)) continue;
      lo[k] = fminf(lo[k], v);
      hi[k] = fmaxf(hi[k], v);
    }
  float far = 100.0f;
  if (lo[0] <= hi[0]) {
    /* farthest box corner, doubled: animated objects move beyond the
     * object-space box */
    float d2 = 0.0f;
    const float e[3] = {eye.x, eye.y, eye.z};
    for (int k = 0; k < 3; k++) {
      const float d = fmaxf(fabsf(e[k] - lo[k]), fabsf(e[k] - hi[k]));
      d2 += d * d;
    }
    far = fmaxf(2.0f * sqrtf(d2), 1e-2f);
  }
  *z_far = far;
  *z_near = far * 1e-5f;
}

/* ---- matrices and rays ------------------------------------------------------- */

static float halton(uint32_t index, uint32_t base) {
  float f = 1.0f, r = 0.0f;
  while (index > 0) {
    f /= (float)base;
    r += f * (float)(index % base);
    index /= base;
  }
  return r;
}

void hush__camera_jitter(uint32_t frame, float jitter[2]) {
  const uint32_t i = frame % 16u + 1u;
  jitter[0] = halton(i, 2) - 0.5f;
  jitter[1] = halton(i, 3) - 0.5f;
}

int hush__camera_setup(hush_render_camera *cam, const hush_camera_pose *pose, int fov_axis_x,
                       uint32_t width, uint32_t height, float z_near, float z_far, uint32_t frame,
                       int jitter) {
  memset(cam, 0, sizeof *cam);
  if (width == 0 || height == 0) return 0;
  if (!(pose->fov_deg > 0.0f && pose->fov_deg < 180.0f)) return 0;
  const hush_vec3 eye = hush_v3(pose->position[0], pose->position[1], pose->position[2]);
  const hush_vec3 target = hush_v3(pose->target[0], pose->target[1], pose->target[2]);
  const hush_vec3 up = hush_v3(pose->up[0], pose->up[1], pose->up[2]);
  const hush_vec3 f = hush_v3_sub(target, eye);
  if (hush_v3_length(f) <= 0.0f) return 0;
  const hush_vec3 side = hush_v3_cross(hush_v3_normalize(f), hush_v3_normalize(up));
  if (!(hush_v3_length(side) > 1e-6f)) return 0;

  const float aspect = (float)width / (float)height;
  const float tan_half = tanf(pose->fov_deg * 0.5f * CAM_PI / 180.0f);
  cam->width = width;
  cam->height = height;
  cam->tan_half_x = fov_axis_x ? tan_half : tan_half * aspect;
  cam->tan_half_y = fov_axis_x ? tan_half / aspect : tan_half;
  const float fov_y = 2.0f * atanf(cam->tan_half_y) * 180.0f / CAM_PI;
  hush_m4_look_at(cam->world_to_view, eye, target, up);
  hush_m4_perspective(cam->view_to_clip, fov_y, aspect, z_near, z_far);
  if (!hush_m4_invert(cam->view_to_world, cam->world_to_view)) return 0;
  cam->eye = eye;
  cam->z_near = z_near;
  cam->z_far = z_far;
  if (jitter) hush__camera_jitter(frame, cam->jitter);
  return 1;
}

hush_vec3 hush__camera_ray(const hush_render_camera *cam, float px, float py) {
  /* the inverse of px = (ndc_x + 1) / 2 * width, py = (1 - ndc_y) / 2 * height */
  const float ndc_x = px / (float)cam->width * 2.0f - 1.0f;
  const float ndc_y = 1.0f - py / (float)cam->height * 2.0f;
  const float vx = ndc_x * cam->tan_half_x, vy = ndc_y * cam->tan_half_y;
  const hush_vec4 d = hush_m4_mul_v4(cam->view_to_world, vx, vy, -1.0f, 0.0f);
  return hush_v3_normalize(hush_v3(d.x, d.y, d.z));
}

int hush__camera_project(const hush_render_camera *cam, hush_vec3 p, float w, float *px, float *py) {
  const hush_vec4 v = hush_m4_mul_v4(cam->world_to_view, p.x, p.y, p.z, w);
  const hush_vec4 c = hush_m4_mul_v4(cam->view_to_clip, v.x, v.y, v.z, w == 0.0f ? 0.0f : 1.0f);
  if (!(c.w > 0.0f)) return 0;
  *px = (c.x / c.w + 1.0f) * 0.5f * (float)cam->width;
  *py = (1.0f - c.y / c.w) * 0.5f * (float)cam->height;
  return isfinite(*px) && isfinite(*py);
}

/* ---- camera-path.json ----------------------------------------------------------- */

static hush_status read_text(hush_device device, const char *file, char **text, size_t *len) {
  FILE *f = fopen(file, "rb");
  if (!f) return hush__fail(device, HUSH_ERROR_IO, "cannot open '%s': %s", file, strerror(errno));
  char *buf = NULL;
  size_t size = 0, cap = 0;
  for (;;) {
    if (size + 4096 + 1 > cap) {
      cap = cap ? 2 * cap : 65536;
      char *grown = realloc(buf, cap);
      if (!grown) {
        free(buf);
        fclose(f);
        return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'", file);
      }
      buf = grown;
    }
    const size_t got = fread(buf + size, 1, cap - size - 1, f);
    size += got;
    if (got == 0) break;
    if ((long long)size > PATH_MAX_BYTES) {
      free(buf);
      fclose(f);
      return hush__fail(device, HUSH_ERROR_UNSUPPORTED, "'%s' is larger than %lld bytes", file,
                        PATH_MAX_BYTES);
    }
  }
  const int failed = ferror(f);
  fclose(f);
  if (failed) {
    free(buf);
    return hush__fail(device, HUSH_ERROR_IO, "cannot read '%s'", file);
  }
  buf[size] = '\0';
  *text = buf;
  *len = size;
  return HUSH_OK;
}

static int read_vec3(const cJSON *obj, const char *key, float out[3]) {
  const cJSON *a = cJSON_GetObjectItemCaseSensitive(obj, key);
  if (!cJSON_IsArray(a) || cJSON_GetArraySize(a) != 3) return 0;
  for (int k = 0; k < 3; k++) {
    const cJSON *e = cJSON_GetArrayItem(a, k);
    if (!cJSON_IsNumber(e) || !isfinite(e->valuedouble)) return 0;
    out[k] = (float)e->valuedouble;
  }
  return 1;
}

static hush_status parse_path(hush_device device, const char *file, const cJSON *root,
                              hush_camera_path *path) {
  if (!cJSON_IsObject(root))
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: expected a JSON object", file);
  const cJSON *axis = cJSON_GetObjectItemCaseSensitive(root, "fov_axis");
  path->fov_axis_x = 1;
  if (axis) {
    if (!cJSON_IsString(axis) || (strcmp(axis->valuestring, "x") && strcmp(axis->valuestring, "y")))
      return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: fov_axis: expected \"x\" or \"y\"", file);
    path->fov_axis_x = axis->valuestring[0] == 'x';
  }
  const cJSON *res = cJSON_GetObjectItemCaseSensitive(root, "resolution");
  if (res) {
    const cJSON *w = cJSON_GetArrayItem(res, 0), *h = cJSON_GetArrayItem(res, 1);
    if (!cJSON_IsArray(res) || cJSON_GetArraySize(res) != 2 || !cJSON_IsNumber(w) ||
        !cJSON_IsNumber(h) || w->valuedouble < 1 || h->valuedouble < 1 || w->valuedouble > 65536 ||
        h->valuedouble > 65536)
      return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: resolution: expected [width, height]",
                        file);
    path->width = (uint32_t)w->valuedouble;
    path->height = (uint32_t)h->valuedouble;
  }
  const cJSON *frames = cJSON_GetObjectItemCaseSensitive(root, "frames");
  if (!cJSON_IsArray(frames) || cJSON_GetArraySize(frames) < 1)
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: frames: expected a non-empty array", file);
  const uint32_t n = (uint32_t)cJSON_GetArraySize(frames);
  path->frames = calloc(n, sizeof *path->frames);
  if (!path->frames) return hush__fail(device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  path->frame_count = n;
  uint32_t i = 0;
  const cJSON *fr;
  cJSON_ArrayForEach(fr, frames) {
    hush_camera_pose *p = &path->frames[i];
    const cJSON *fov = cJSON_GetObjectItemCaseSensitive(fr, "fov_deg");
    const char *bad = !read_vec3(fr, "position", p->position) ? "position"
                      : !read_vec3(fr, "target", p->target)   ? "target"
                      : !read_vec3(fr, "up", p->up)           ? "up"
                      : !cJSON_IsNumber(fov) || !(fov->valuedouble > 0 && fov->valuedouble < 180)
                          ? "fov_deg"
                          : NULL;
    if (bad)
      return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: frames[%u].%s: %s", file, i, bad,
                        strcmp(bad, "fov_deg") ? "expected 3 finite numbers"
                                               : "expected a number in (0, 180)");
    p->fov_deg = (float)fov->valuedouble;
    i++;
  }
  return HUSH_OK;
}

hush_status hush__camera_path_load(hush_device device, const char *file, hush_camera_path *path) {
  memset(path, 0, sizeof *path);
  char *text = NULL;
  size_t len = 0;
  hush_status st = read_text(device, file, &text, &len);
  if (st != HUSH_OK) return st;
  const char *end = NULL;
  cJSON *root = cJSON_ParseWithLengthOpts(text, len + 1, &end, 1);
  if (!root) {
    const size_t at = end && end >= text && end <= text + len ? (size_t)(end - text) : len;
    free(text);
    return hush__fail(device, HUSH_ERROR_CORRUPT, "%s: not valid JSON (error at byte %zu)", file,
                      at);
  }
  st = parse_path(device, file, root, path);
  cJSON_Delete(root);
  free(text);
  if (st != HUSH_OK) {
    free(path->frames);
    memset(path, 0, sizeof *path);
  }
  return st;
}

void hush__camera_move_init(hush_camera_move_setup *m, const hush_scene *scene,
                            hush_camera_move move, const hush_camera_path *path, uint32_t width,
                            uint32_t height, int jitter, uint32_t first_frame) {
  m->scene = scene;
  m->move = move;
  m->path = path;
  m->width = width;
  m->height = height;
  m->jitter = jitter;
  hush_camera_pose pose;
  int axis_x;
  hush__camera_pose(scene, move, path, first_frame, &pose, &axis_x);
  hush__camera_clip_range(scene, hush_v3(pose.position[0], pose.position[1], pose.position[2]),
                          &m->z_near, &m->z_far);
  /* margin: later frames' eyes may see a little more of the scene */
  m->z_near *= 2.0f;
  m->z_far *= 2.0f;
}

int hush__camera_move_frame(const hush_camera_move_setup *m, uint32_t frame, hush_render_camera *cam,
                            hush_render_camera *prev, int *have_prev) {
  hush_camera_pose pose;
  int axis_x;
  hush__camera_pose(m->scene, m->move, m->path, frame, &pose, &axis_x);
  if (!hush__camera_setup(cam, &pose, axis_x, m->width, m->height, m->z_near, m->z_far, frame,
                          m->jitter))
    return 0;
  *have_prev = 0;
  if (frame > 0) {
    hush__camera_pose(m->scene, m->move, m->path, frame - 1, &pose, &axis_x);
    *have_prev = hush__camera_setup(prev, &pose, axis_x, m->width, m->height, m->z_near, m->z_far,
                                    frame - 1, m->jitter);
  }
  return 1;
}

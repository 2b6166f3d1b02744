/*
 * scene.h — the renderer's scene: triangles grouped into rigid objects (some
 * animated), materials converted from the MTL conventions of
 * ../shared/scenes/README.md, textures, lights (emissive triangles, an
 * environment map, sun and sky, sphere lights), the camera and its path, and
 * the Embree scene that traces rays against it.
 *
 * Split of responsibilities:
 *   scene_load.c    scene.json manifests: OBJ/MTL through assimp, JPG/PNG
 *                   textures, EXR environment maps, camera and camera path
 *   scene_builtin.c procedural scenes that need no files (builtin:NAME)
 *   scene.c         Embree set-up, per-frame animation, ray queries, the
 *                   surface at a hit (interpolated normals, uvs, textures)
 *   texture.c       texture storage and filtered lookups
 * The integrator (integrator.c), materials (bsdf.c) and light sampling
 * (lights.c) read this structure; they never touch Embree directly.
 *
 * Geometry identity: every triangle has a global index (0..triangle_count-1)
 * that is stable across frames; a hit reports it with barycentrics (u, v)
 * (the point is (1-u-v) p0 + u p1 + v p2 in object space). This pair is the
 * visibility buffer: the same surface point can be found in any frame, also
 * on a moving object, by hush__scene_point() with that frame's transforms.
 */
#ifndef HUSH_RENDER_SCENE_H
#define HUSH_RENDER_SCENE_H

#include "hush.h"
#include "core/hmath.h"

#include <stdint.h>

/* ---- textures ------------------------------------------------------------ */

typedef struct hush_texture {
  char name[256];         /* file name, for messages */
  uint32_t width, height;
  int channels;           /* 1..4 */
  float *texels;          /* width * height * channels, linear (sRGB decoded
                           * for colour maps), row 0 at the TOP of the image */
} hush_texture;

/* ---- materials ------------------------------------------------------------ */

typedef enum hush_material_type {
  HUSH_MAT_DIFFUSE = 0,    /* Lambert: Kd / map_Kd */
  HUSH_MAT_PLASTIC = 1,    /* dielectric coat (Ks, Ni, roughness Pr; 0 = smooth) over Lambert */
  HUSH_MAT_CONDUCTOR = 2,  /* GGX conductor (Pm 1), reflectance Ks, roughness Pr (0 = mirror) */
  HUSH_MAT_DIELECTRIC = 3  /* smooth glass (illum 7, d 0), index Ni */
} hush_material_type;

typedef struct hush_material {
  char name[128];
  hush_material_type type;
  float diffuse[3];        /* Kd (linear) */
  int diffuse_texture;     /* index into textures, -1 none (map_Kd replaces Kd) */
  float specular[3];       /* Ks: coat reflectance (plastic) or conductor colour */
  float roughness;         /* GGX alpha (MTL Pr), 0 = smooth */
  float ior;               /* Ni (1.5 when absent) */
  float emission[3];       /* Ke: emitted radiance; non-zero makes the triangles lights */
  int alpha_texture;       /* map_d: -1 none; texels with alpha < 0.5 are holes */
  float opacity;           /* d (for masks without a map: 1) */
  int two_sided;           /* shade both sides (the Mitsuba twosided wrapper) */
} hush_material;

/* ---- objects and animation -------------------------------------------------- */

/* How a rigid object moves: its object-to-world transform at frame f is
 * translate(translation + f * velocity) * rotate_y(f * spin_deg_per_frame about
 * pivot). Static objects have animated == 0 and an identity transform. */
typedef struct hush_motion {
  int animated;
  float translation[3];
  float velocity[3];       /* world units per frame */
  float pivot[3];
  float spin_deg_per_frame;
  /* back and forth instead of forever: position follows a triangle wave of
   * this period in frames (0: linear motion) */
  uint32_t period;
} hush_motion;

typedef struct hush_object {
  char name[64];
  uint32_t first_triangle, triangle_count; /* a range of the global triangles */
  hush_motion motion;
} hush_object;

/* ---- lights ------------------------------------------------------------------ */

typedef enum hush_env_type {
  HUSH_ENV_NONE = 0,
  HUSH_ENV_CONSTANT = 1,   /* uniform radiance env_color */
  HUSH_ENV_MAP = 2,        /* latitude-longitude map, Mitsuba convention (+Y up locally) */
  HUSH_ENV_SUNSKY = 3      /* sky model plus a sun disc (see lights.c for the model) */
} hush_env_type;

typedef struct hush_environment {
  hush_env_type type;
  float color[3];          /* CONSTANT */
  int texture;             /* MAP: index into textures */
  float to_world[16];      /* MAP: local-to-world rotation, column-major */
  float scale;             /* MAP: radiance multiplier */
  /* SUNSKY (scene.json "sunsky" light) */
  float sun_direction[3];  /* unit, towards the sun */
  float turbidity, sky_scale, sun_scale, sun_radius_scale;
} hush_environment;

/* A spherical area light (synthetic scenes). It may move along a straight
 * back-and-forth path, jump once to another place and switch off at a
 * given frame. */
typedef struct hush_sphere_light {
  float center[3];
  float radius;
  float radiance[3];       /* emitted radiance of its surface */
  float velocity[3];       /* world units per frame */
  uint32_t period;         /* back-and-forth period in frames (0: linear) */
  int32_t off_from_frame;  /* -1: always on; else dark from this frame on */
  float jump[3];           /* added to the centre from jump_from_frame on (a step) */
  uint32_t jump_from_frame; /* 0 with jump 0: never jumps */
} hush_sphere_light;

/* ---- camera --------------------------------------------------------------------- */

typedef struct hush_camera_pose {
  float position[3], target[3], up[3];
  float fov_deg;           /* along fov_axis */
} hush_camera_pose;

typedef struct hush_camera_path {
  int fov_axis_x;          /* 1: fov_deg is horizontal, 0: vertical */
  uint32_t width, height;  /* the resolution the path was made for (0: none) */
  uint32_t frame_count;
  hush_camera_pose *frames; /* owned */
} hush_camera_path;

/* ---- the scene ------------------------------------------------------------------- */

typedef struct hush_scene {
  char name[128];
  char dir[4096];          /* folder of scene.json ("" for built-in scenes) */

  /* Geometry in OBJECT space (world space for static objects). */
  uint32_t vertex_count;
  float *positions;        /* 3 per vertex */
  float *normals;          /* 3 per vertex, or NULL: geometric normals */
  float *uvs;              /* 2 per vertex, or NULL */
  uint32_t triangle_count;
  uint32_t *indices;       /* 3 per triangle */
  uint32_t *triangle_material; /* 1 per triangle */
  uint32_t *triangle_object;   /* 1 per triangle */

  hush_object *objects;
  uint32_t object_count;
  hush_material *materials;
  uint32_t material_count;
  hush_texture *textures;
  uint32_t texture_count;

  hush_environment env;
  hush_sphere_light *spheres;
  uint32_t sphere_count;

  int two_sided;                 /* manifest default for all materials */
  int two_sided_emitters;        /* emissive triangles emit from both sides; else only from
                                  * their front (the side of the stored normals, as
                                  * hush_surface.back_face; Mitsuba's and PBRT's area lights) */
  hush_camera_pose camera;       /* the manifest's camera */
  int camera_fov_axis_x;
  uint32_t width, height;        /* the manifest's resolution */
  hush_camera_path path;         /* frame_count 0 when the scene has none */

  uint32_t skipped_triangles;    /* degenerate or NaN triangles dropped at load */
  uint32_t emissive_triangles;   /* triangles whose material has non-zero emission */

  /* Set by hush__scene_commit / hush__scene_set_frame (scene.c). */
  void *rtc_device;              /* RTCDevice */
  void *rtc_scene;               /* RTCScene: static geometry + one instance per animated object */
  uint32_t frame;                /* the frame the transforms are set for */
  float *object_to_world;        /* 16 per object, column-major, for `frame` */
  void *rtc_data;                /* scene.c's private Embree state (buffers, filters) */
} hush_scene;

/* Loads PATH/scene.json (format hush-scene/1). Errors name the file and the
 * field: "scene.json: lights[0].type: unknown light type 'spot'". A scene
 * with no light loads (it renders black; the caller warns). The caller owns
 * *scene: hush__scene_free(). */
hush_status hush__scene_load(hush_device device, const char *path, hush_scene *scene);

/* A procedural scene by name ("cornell", "courtyard", ...); NULL-terminated
 * list of names in hush__scene_builtin_names. */
hush_status hush__scene_builtin(hush_device device, const char *name, hush_scene *scene);
extern const char *const hush__scene_builtin_names[];
extern const char *const hush__scene_builtin_docs[];

void hush__scene_free(hush_scene *scene);

/* Builds the Embree scene (once, after loading). */
hush_status hush__scene_commit(hush_device device, hush_scene *scene);
/* Sets animated objects' transforms for frame f and recommits what moved. */
hush_status hush__scene_set_frame(hush_device device, hush_scene *scene, uint32_t frame);
/* object_to_world of object o at any frame (does not change the scene). */
void hush__scene_object_transform(const hush_scene *scene, uint32_t object, uint32_t frame,
                                  float out[16]);
/* A sphere light's centre at frame f, and whether it is on. */
int hush__scene_sphere_at(const hush_scene *scene, uint32_t light, uint32_t frame, float center[3]);

/* ---- ray queries (thread-safe after commit / set_frame) ------------------------ */

typedef struct hush_hit {
  uint32_t triangle;       /* global index; UINT32_MAX: no hit */
  float u, v;              /* barycentrics */
  float t;                 /* ray distance */
} hush_hit;

/* Closest hit along o + t d for t in (tnear, tfar); alpha-masked texels are
 * skipped. Returns 1 on a hit. */
int hush__scene_intersect(const hush_scene *scene, const float o[3], const float d[3], float tnear,
                          float tfar, hush_hit *hit);
/* Closest hits of a packet of camera rays from one origin o: lane i has
 * direction d[i] (t in (0, inf)) when bit i of `lanes` is set; other lanes
 * get no hit. Embree's packet traversal is ~3x faster than single rays for
 * the coherent rays of a pixel block. A lane's hit can differ from
 * hush__scene_intersect's where two triangles tie exactly (coplanar
 * duplicates, shared edges), and may depend on the other lanes, so a caller
 * that must reproduce a hit traces the same packet again. */
#define HUSH_PACKET 16
void hush__scene_intersect_packet(const hush_scene *scene, const float o[3],
                                  const float d[HUSH_PACKET][3], uint32_t lanes,
                                  hush_hit hits[HUSH_PACKET]);
/* Whether anything opaque lies along o + t d for t in (tnear, tfar). */
int hush__scene_occluded(const hush_scene *scene, const float o[3], const float d[3], float tnear,
                         float tfar);

/* Everything shading needs at a hit, in WORLD space for the current frame. */
typedef struct hush_surface {
  hush_vec3 p;             /* position */
  hush_vec3 ng;            /* geometric normal (unit), facing the ray's origin side
                            * for two-sided materials */
  hush_vec3 ns;            /* shading normal (unit, interpolated), on ng's side */
  float uv[2];
  uint32_t material;
  uint32_t object;
  float albedo[3];         /* diffuse reflectance at the point (texture applied) */
  int back_face;           /* 1 if the ray hit the side opposite the stored normal */
} hush_surface;

/* Fills s for a hit of a ray with direction d. */
void hush__scene_surface(const hush_scene *scene, const hush_hit *hit, const float d[3],
                         hush_surface *s);

/* Asks the cache for what hush__scene_surface will read of `triangle`
 * (its shading record), so that the miss of an incoherent hit overlaps
 * other work (a shadow ray's traversal). A hint: no effect on results;
 * triangle UINT32_MAX (no hit) does nothing. */
void hush__scene_prefetch_surface(const hush_scene *scene, uint32_t triangle);

/* Whether the triangle is flat-shaded: its stored vertex normals (if any)
 * are all its face normal, so a mirror on it reflects as a plane (the
 * renderer's primary surface replacement, render.h). */
int hush__scene_triangle_flat(const hush_scene *scene, uint32_t triangle);

/* World position of (triangle, u, v) at frame f (forward projection of a
 * visibility-buffer sample into another frame). */
hush_vec3 hush__scene_point(const hush_scene *scene, uint32_t triangle, float u, float v,
                            uint32_t frame);

/* ---- textures (texture.c) ----------------------------------------------------- */

/* Bilinear lookup with wrap-around; uv (0,0) is the BOTTOM-left of the image
 * (OBJ convention). Writes `channels` values to out (up to 4). */
void hush__texture_sample(const hush_texture *t, float u, float v, float out[4]);

typedef enum hush_texture_kind {
  HUSH_TEXTURE_SRGB = 0,   /* colour map: RGB, 8-bit sRGB decoded to linear */
  HUSH_TEXTURE_ALPHA = 1,  /* opacity: 1 channel, the alpha channel (or grey) as stored */
  HUSH_TEXTURE_LINEAR = 2  /* RGB as stored (EXR environment maps) */
} hush_texture_kind;

/* Loads a JPG, PNG or EXR file (by extension). `what` prefixes error
 * messages ("scene.mtl: Leaves: map_d"). A missing file is
 * HUSH_ERROR_NOT_FOUND. On failure *t is left empty (safe to free). */
hush_status hush__texture_load(hush_device device, const char *path, const char *what,
                               hush_texture_kind kind, hush_texture *t);
/* A zero-filled texture to fill procedurally. */
hush_status hush__texture_init(hush_device device, hush_texture *t, const char *name,
                               uint32_t width, uint32_t height, int channels);
void hush__texture_free(hush_texture *t);

#endif

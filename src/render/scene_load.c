/*
 * scene_load.c — loads a "hush-scene/1" manifest (scene.json): the OBJ mesh
 * through assimp, materials from our own reading of the MTL file (assimp's
 * OBJ importer drops Pr, Pm, illum and the "# mitsuba:" comments that say
 * what each material was), JPG/PNG textures, the environment (EXR map or
 * sun and sky), the camera and the optional camera path.
 * docs/scenes.md describes the manifest and the material mapping.
 *
 * Every error names the file and the field. On failure the scene is freed
 * and left zeroed, so hush__scene_free() on it is always safe.
 */
#include "render/scene.h"

#include "core/device.h"
#include "core/timer.h"

#include <assimp/cfileio.h>
#include <assimp/cimport.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <cjson/cJSON.h>
#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define PATH_MAX_LEN 4096
/* scene.json and camera-path.json are small; anything larger is a mistake */
#define JSON_MAX_BYTES ((long)64 << 20)

/* ------------------------------------------------------------------------ */
/* Small helpers                                                            */
/* ------------------------------------------------------------------------ */

/* Where errors go and what they are about. */
typedef struct ctx {
  hush_device device;
  const char *file; /* the JSON or MTL file the current field is in */
} ctx;

/* Copies src into dst[size], cutting it short if it must (names only). */
static void copy_name(char *dst, size_t size, const char *src) {
  const size_t n = strnlen(src, size - 1);
  memcpy(dst, src, n);
  dst[n] = '\0';
}

static int is_dir(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

static int is_file(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

/* dir/rel, with MTL-style backslashes turned into slashes. */
static hush_status join_path(const ctx *c, const char *dir, const char *rel, const char *field,
                             char out[PATH_MAX_LEN]) {
  int n;
  if (rel[0] == '/' || !dir[0]) n = snprintf(out, PATH_MAX_LEN, "%s", rel);
  else n = snprintf(out, PATH_MAX_LEN, "%s/%s", dir, rel);
  if (n < 0 || n >= PATH_MAX_LEN)
    return hush__fail(c->device, HUSH_ERROR_INVALID_ARGUMENT, "%s: %s: path too long", c->file,
                      field);
  for (char *p = out; *p; p++)
    if (*p == '\\') *p = '/';
  return HUSH_OK;
}

static hush_status read_text(const ctx *c, const char *path, const char *field, char **text) {
  *text = NULL;
  FILE *f = fopen(path, "rb");
  if (!f) {
    if (errno == ENOENT)
      return hush__fail(c->device, HUSH_ERROR_NOT_FOUND, "%s%s%s: '%s' not found",
                        field ? c->file : "", field ? ": " : "", field ? field : path, path);
    return hush__fail(c->device, HUSH_ERROR_IO, "cannot open '%s': %s", path, strerror(errno));
  }
  long size = -1;
  if (fseek(f, 0, SEEK_END) == 0) size = ftell(f);
  if (size < 0 || size > JSON_MAX_BYTES || fseek(f, 0, SEEK_SET) != 0) {
    fclose(f);
    return hush__fail(c->device, HUSH_ERROR_IO, "cannot read '%s' (or it is over 64 MiB)", path);
  }
  char *buf = malloc((size_t)size + 1);
  if (!buf) {
    fclose(f);
    return hush__fail(c->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'", path);
  }
  const size_t got = fread(buf, 1, (size_t)size, f);
  fclose(f);
  if (got != (size_t)size) {
    free(buf);
    return hush__fail(c->device, HUSH_ERROR_IO, "cannot read '%s'", path);
  }
  buf[size] = '\0';
  *text = buf;
  return HUSH_OK;
}

static hush_status parse_json(const ctx *c, const char *path, const char *field, cJSON **out) {
  char *text;
  *out = NULL;
  hush_status st = read_text(c, path, field, &text);
  if (st != HUSH_OK) return st;
  const char *end = NULL;
  cJSON *root = cJSON_ParseWithOpts(text, &end, 0);
  if (!root) {
    int line = 1;
    for (const char *p = text; end && p < end && *p; p++)
      if (*p == '\n') line++;
    st = hush__fail(c->device, HUSH_ERROR_CORRUPT, "%s: malformed JSON at line %d", path, line);
    free(text);
    return st;
  }
  free(text);
  if (!cJSON_IsObject(root)) {
    cJSON_Delete(root);
    return hush__fail(c->device, HUSH_ERROR_CORRUPT, "%s: the top level is not a JSON object",
                      path);
  }
  *out = root;
  return HUSH_OK;
}

static hush_status bad_field(const ctx *c, const char *field, const char *what) {
  return hush__fail(c->device, HUSH_ERROR_CORRUPT, "%s: %s: %s", c->file, field, what);
}

/* A number field; absent: *out = def, or an error if required. */
static hush_status get_number(const ctx *c, const cJSON *obj, const char *key, const char *field,
                              int required, double def, double *out) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
  *out = def;
  if (!it) return required ? bad_field(c, field, "missing") : HUSH_OK;
  if (!cJSON_IsNumber(it) || !isfinite(it->valuedouble))
    return bad_field(c, field, "not a finite number");
  *out = it->valuedouble;
  return HUSH_OK;
}

static hush_status get_floats(const ctx *c, const cJSON *obj, const char *key, const char *field,
                              int n, float *out) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
  if (!it) return bad_field(c, field, "missing");
  if (!cJSON_IsArray(it) || cJSON_GetArraySize(it) != n) {
    char what[64];
    snprintf(what, sizeof what, "not an array of %d numbers", n);
    return bad_field(c, field, what);
  }
  int i = 0;
  const cJSON *e;
  cJSON_ArrayForEach(e, it) {
    if (!cJSON_IsNumber(e) || !isfinite(e->valuedouble))
      return bad_field(c, field, "holds something that is not a finite number");
    out[i++] = (float)e->valuedouble;
  }
  return HUSH_OK;
}

static const char *get_string(const cJSON *obj, const char *key) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
  return cJSON_IsString(it) ? it->valuestring : NULL;
}

/* ------------------------------------------------------------------------ */
/* Camera and camera path                                                   */
/* ------------------------------------------------------------------------ */

static hush_status parse_fov_axis(const ctx *c, const cJSON *obj, const char *field, int *x) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, "fov_axis");
  *x = 0;
  if (!it) return HUSH_OK;
  if (!cJSON_IsString(it) || (strcmp(it->valuestring, "x") && strcmp(it->valuestring, "y")))
    return bad_field(c, field, "must be \"x\" or \"y\"");
  *x = it->valuestring[0] == 'x';
  return HUSH_OK;
}

static hush_status parse_pose(const ctx *c, const cJSON *obj, const char *prefix,
                              hush_camera_pose *pose) {
  char field[96];
  if (!cJSON_IsObject(obj)) return bad_field(c, prefix, "not an object");
  static const char *const keys[3] = {"position", "target", "up"};
  float *dst[3] = {pose->position, pose->target, pose->up};
  for (int k = 0; k < 3; k++) {
    snprintf(field, sizeof field, "%s.%s", prefix, keys[k]);
    const hush_status st = get_floats(c, obj, keys[k], field, 3, dst[k]);
    if (st != HUSH_OK) return st;
  }
  snprintf(field, sizeof field, "%s.fov_deg", prefix);
  double fov;
  const hush_status st = get_number(c, obj, "fov_deg", field, 1, 0.0, &fov);
  if (st != HUSH_OK) return st;
  if (!(fov > 0.0 && fov < 180.0)) return bad_field(c, field, "must lie in (0, 180)");
  pose->fov_deg = (float)fov;
  return HUSH_OK;
}

static hush_status parse_resolution(const ctx *c, const cJSON *obj, const char *field,
                                    uint32_t *w, uint32_t *h) {
  *w = *h = 0;
  if (!cJSON_GetObjectItemCaseSensitive(obj, "resolution")) return HUSH_OK;
  float r[2];
  const hush_status st = get_floats(c, obj, "resolution", field, 2, r);
  if (st != HUSH_OK) return st;
  if (!(r[0] >= 1 && r[1] >= 1 && r[0] <= 65536 && r[1] <= 65536) || r[0] != floorf(r[0]) ||
      r[1] != floorf(r[1]))
    return bad_field(c, field, "must be two whole numbers in 1..65536");
  *w = (uint32_t)r[0];
  *h = (uint32_t)r[1];
  return HUSH_OK;
}

static hush_status load_camera_path(const ctx *c, hush_scene *scene, const char *rel) {
  char path[PATH_MAX_LEN];
  hush_status st = join_path(c, scene->dir, rel, "camera_path", path);
  if (st != HUSH_OK) return st;
  if (!is_file(path))
    return hush__fail(c->device, HUSH_ERROR_NOT_FOUND, "%s: camera_path: '%s' not found", c->file,
                      path);
  cJSON *root;
  st = parse_json(c, path, "camera_path", &root);
  if (st != HUSH_OK) return st;
  const ctx pc = {c->device, path};
  hush_camera_path *cp = &scene->path;
  st = parse_fov_axis(&pc, root, "fov_axis", &cp->fov_axis_x);
  if (st == HUSH_OK) st = parse_resolution(&pc, root, "resolution", &cp->width, &cp->height);
  const cJSON *frames = cJSON_GetObjectItemCaseSensitive(root, "frames");
  if (st == HUSH_OK && !cJSON_IsArray(frames))
    st = bad_field(&pc, "frames", "missing or not an array");
  if (st == HUSH_OK) {
    const int n = cJSON_GetArraySize(frames);
    cp->frames = calloc(n > 0 ? (size_t)n : 1, sizeof *cp->frames);
    if (!cp->frames) st = hush__fail(c->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
    const cJSON *f;
    uint32_t i = 0;
    cJSON_ArrayForEach(f, frames) {
      if (st != HUSH_OK) break;
      char field[48];
      snprintf(field, sizeof field, "frames[%u]", i);
      st = parse_pose(&pc, f, field, &cp->frames[i]);
      i++;
    }
    if (st == HUSH_OK) cp->frame_count = i;
  }
  cJSON_Delete(root);
  return st;
}

/* ------------------------------------------------------------------------ */
/* The MTL file                                                             */
/* ------------------------------------------------------------------------ */

/* One material as the MTL states it, before mapping. */
typedef struct mtl_entry {
  char name[128];
  char mitsuba[128]; /* the "# mitsuba: ..." comment above newmtl */
  float kd[3], ks[3], ke[3];
  float ni, pr, pm, d, ns;
  int has_ni, has_pr, has_d, has_ns, illum;
  char map_kd[PATH_MAX_LEN];
  char map_d[PATH_MAX_LEN];
  int line; /* of newmtl, for messages */
  int keys; /* statements seen so far */
} mtl_entry;

typedef struct mtl_file {
  mtl_entry *entries;
  uint32_t count;
} mtl_file;

static char *trim(char *s) {
  while (isspace((unsigned char)*s)) s++;
  char *e = s + strlen(s);
  while (e > s && isspace((unsigned char)e[-1])) *--e = '\0';
  return s;
}

/* Up to n numbers; a single number fills all n (MTL allows "Ks 0.04"). */
static void parse_floats(const char *s, int n, float *out) {
  char *end;
  int got = 0;
  for (; got < n; got++) {
    const float v = strtof(s, &end);
    if (end == s) break;
    out[got] = v;
    s = end;
  }
  for (int i = got == 0 ? 0 : got; i < n; i++) out[i] = got ? out[got - 1] : 0.0f;
}

/* The file name of a map statement, after any "-option value" pairs;
 * it may hold spaces. */
static void parse_map_name(char *value, char out[PATH_MAX_LEN]) {
  char *s = trim(value);
  while (*s == '-') {
    while (*s && !isspace((unsigned char)*s)) s++; /* the option */
    for (;;) {                                     /* its numeric or on/off arguments */
      while (isspace((unsigned char)*s)) s++;
      char *end;
      strtod(s, &end);
      if (end != s && (isspace((unsigned char)*end) || !*end)) s = end;
      else if (strncmp(s, "on ", 3) == 0 || strncmp(s, "off ", 4) == 0) s += s[1] == 'n' ? 3 : 4;
      else break;
    }
  }
  snprintf(out, PATH_MAX_LEN, "%s", s);
}

static void mtl_defaults(mtl_entry *e) {
  memset(e, 0, sizeof *e);
  e->kd[0] = e->kd[1] = e->kd[2] = 0.8f;
  e->ni = 1.5f;
  e->d = 1.0f;
  e->illum = 2;
}

static hush_status parse_mtl(const ctx *c, const char *path, mtl_file *mtl) {
  char *text;
  memset(mtl, 0, sizeof *mtl);
  hush_status st = read_text(c, path, NULL, &text);
  if (st != HUSH_OK) return st;
  uint32_t cap = 0;
  char comment[128] = "";
  int line_no = 0;
  char *save = NULL;
  for (char *line = strtok_r(text, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
    line_no++;
    char *s = trim(line);
    if (*s == '#') {
      if (strncmp(s, "# mitsuba:", 10) != 0) continue;
      /* The comment may sit right below its newmtl or above it: one that
       * follows a newmtl before any key belongs to it, any other one waits
       * for the next newmtl. */
      mtl_entry *cur = mtl->count ? &mtl->entries[mtl->count - 1] : NULL;
      if (cur && !cur->mitsuba[0] && !cur->keys) copy_name(cur->mitsuba, sizeof cur->mitsuba,
                                                           trim(s + 10));
      else copy_name(comment, sizeof comment, trim(s + 10));
      continue;
    }
    char *hash = strchr(s, '#'); /* trailing comments ("Ka 0.6 0 0 # Red") */
    if (hash && strncmp(s, "map_", 4) != 0) *hash = '\0';
    char *value = s;
    while (*value && !isspace((unsigned char)*value)) value++;
    if (*value) *value++ = '\0';
    value = trim(value);
    if (strcmp(s, "newmtl") == 0) {
      if (mtl->count == cap) {
        cap = cap ? cap * 2 : 32;
        mtl_entry *grown = realloc(mtl->entries, cap * sizeof *grown);
        if (!grown) {
          free(text);
          return hush__fail(c->device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory reading '%s'",
                            path);
        }
        mtl->entries = grown;
      }
      mtl_entry *e = &mtl->entries[mtl->count++];
      mtl_defaults(e);
      copy_name(e->name, sizeof e->name, value);
      copy_name(e->mitsuba, sizeof e->mitsuba, comment);
      e->line = line_no;
      comment[0] = '\0';
      continue;
    }
    if (mtl->count == 0) continue;
    mtl_entry *e = &mtl->entries[mtl->count - 1];
    if (*s) e->keys++;
    if (strcmp(s, "Kd") == 0) parse_floats(value, 3, e->kd);
    else if (strcmp(s, "Ks") == 0) parse_floats(value, 3, e->ks);
    else if (strcmp(s, "Ke") == 0) parse_floats(value, 3, e->ke);
    else if (strcmp(s, "Ni") == 0) parse_floats(value, 1, &e->ni), e->has_ni = 1;
    else if (strcmp(s, "Pr") == 0) parse_floats(value, 1, &e->pr), e->has_pr = 1;
    else if (strcmp(s, "Pm") == 0) parse_floats(value, 1, &e->pm);
    else if (strcmp(s, "Ns") == 0) parse_floats(value, 1, &e->ns), e->has_ns = 1;
    else if (strcmp(s, "d") == 0) parse_floats(value, 1, &e->d), e->has_d = 1;
    else if (strcmp(s, "Tr") == 0 && !e->has_d) {
      float tr = 0.0f;
      parse_floats(value, 1, &tr);
      e->d = 1.0f - tr;
    } else if (strcmp(s, "illum") == 0) e->illum = atoi(value);
    else if (strcmp(s, "map_Kd") == 0) parse_map_name(value, e->map_kd);
    else if (strcmp(s, "map_d") == 0) parse_map_name(value, e->map_d);
    /* anything else (Ka, Tf, map_Bump, stray statements) does not change
     * how we shade */
  }
  free(text);
  return HUSH_OK;
}

static const mtl_entry *mtl_find(const mtl_file *mtl, const char *name) {
  for (uint32_t i = 0; i < mtl->count; i++)
    if (strcmp(mtl->entries[i].name, name) == 0) return &mtl->entries[i];
  return NULL;
}

/* The mtllib an OBJ names (its first one). Scans lines until it finds it:
 * it is nearly always at the top. */
static int find_mtllib(const char *obj_path, char out[PATH_MAX_LEN]) {
  FILE *f = fopen(obj_path, "rb");
  if (!f) return 0;
  char line[PATH_MAX_LEN];
  int found = 0;
  while (!found && fgets(line, sizeof line, f)) {
    char *s = trim(line);
    if (strncmp(s, "mtllib", 6) == 0 && isspace((unsigned char)s[6])) {
      snprintf(out, PATH_MAX_LEN, "%s", trim(s + 6));
      found = 1;
    }
  }
  fclose(f);
  return found;
}

/* ------------------------------------------------------------------------ */
/* Materials and textures                                                   */
/* ------------------------------------------------------------------------ */

typedef struct loader {
  ctx c;
  hush_scene *scene;
  uint32_t texture_cap;
  hush_texture_kind *texture_kinds; /* parallel to scene->textures, for the cache */
  char (*texture_paths)[PATH_MAX_LEN];
  uint32_t file_triangles, file_emissive; /* as the OBJ has them, skipped ones included */
} loader;

/* Index of the texture at rel (loading it the first time), or -1 with an
 * error. */
static hush_status texture_index(loader *l, const char *rel, hush_texture_kind kind,
                                 const char *what, int *index) {
  hush_scene *s = l->scene;
  char path[PATH_MAX_LEN];
  *index = -1;
  hush_status st = join_path(&l->c, s->dir, rel, what, path);
  if (st != HUSH_OK) return st;
  for (uint32_t i = 0; i < s->texture_count; i++) {
    if (l->texture_kinds[i] == kind && strcmp(l->texture_paths[i], path) == 0) {
      *index = (int)i;
      return HUSH_OK;
    }
  }
  if (s->texture_count == l->texture_cap) {
    const uint32_t cap = l->texture_cap ? 2 * l->texture_cap : 8;
    hush_texture *t = realloc(s->textures, cap * sizeof *t);
    if (t) s->textures = t;
    hush_texture_kind *k = realloc(l->texture_kinds, cap * sizeof *k);
    if (k) l->texture_kinds = k;
    char(*p)[PATH_MAX_LEN] = realloc(l->texture_paths, cap * sizeof *p);
    if (p) l->texture_paths = p;
    if (!t || !k || !p) return hush__fail(l->c.device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
    l->texture_cap = cap;
  }
  hush_texture *t = &s->textures[s->texture_count];
  st = hush__texture_load(l->c.device, path, what, kind, t);
  if (st != HUSH_OK) return st;
  l->texture_kinds[s->texture_count] = kind;
  snprintf(l->texture_paths[s->texture_count], PATH_MAX_LEN, "%s", path);
  *index = (int)s->texture_count++;
  return HUSH_OK;
}

static float max3(const float v[3]) {
  return fmaxf(v[0], fmaxf(v[1], v[2]));
}

/* The Mitsuba type at the end of "twosided > roughplastic". */
static const char *mitsuba_type(const mtl_entry *e) {
  const char *gt = strrchr(e->mitsuba, '>');
  const char *s = gt ? gt + 1 : e->mitsuba;
  while (*s == ' ') s++;
  return s;
}

static int type_is(const mtl_entry *e, const char *type) {
  return strcmp(mitsuba_type(e), type) == 0;
}

/* The Mitsuba types the mapping below knows: wrappers (mask, twosided,
 * bumpmap, whose inner type decides) and BSDFs. */
static const char *const known_types[] = {
    "mask",          "twosided",        "bumpmap",        "diffuse",        "roughdiffuse",
    "plastic",       "roughplastic",    "phong",          "conductor",      "roughconductor",
    "dielectric",    "roughdielectric", "thindielectric", NULL};

/* The first word of the "# mitsuba: a > b > c" chain that is not in
 * known_types, copied into bad; 0 when every one is known (or there is no
 * comment). A type this loader does not know must not silently become
 * Lambert: the scene would render, but wrong. */
static int unknown_type(const mtl_entry *e, char *bad, size_t size) {
  const char *s = e->mitsuba;
  while (*s) {
    while (*s == ' ' || *s == '>') s++;
    size_t n = 0;
    while (s[n] && s[n] != ' ' && s[n] != '>') n++;
    if (n == 0) break;
    int known = 0;
    for (int i = 0; known_types[i] && !known; i++)
      known = strlen(known_types[i]) == n && strncmp(known_types[i], s, n) == 0;
    if (!known) {
      snprintf(bad, size, "%.*s", (int)n, s);
      return 1;
    }
    s += n;
  }
  return 0;
}

/* The mapping of docs/scenes.md ("Materials"). */
static void map_material(const mtl_entry *e, int two_sided, hush_material *m) {
  memcpy(m->diffuse, e->kd, sizeof m->diffuse);
  memcpy(m->specular, e->ks, sizeof m->specular);
  memcpy(m->emission, e->ke, sizeof m->emission);
  for (int k = 0; k < 3; k++) {
    if (!(m->emission[k] >= 0.0f)) m->emission[k] = 0.0f;
    m->diffuse[k] = fminf(fmaxf(m->diffuse[k], 0.0f), 1.0f);
    m->specular[k] = fminf(fmaxf(m->specular[k], 0.0f), 1.0f);
  }
  m->ior = e->has_ni && e->ni > 1.0f ? e->ni : 1.5f;
  m->roughness = e->has_pr ? fmaxf(e->pr, 0.0f) : 0.0f;
  m->opacity = fminf(fmaxf(e->d, 0.0f), 1.0f);
  m->two_sided = two_sided || strstr(e->mitsuba, "twosided") != NULL;
  const int glass = (e->illum == 7 && e->has_d && e->d == 0.0f) || type_is(e, "dielectric") ||
                    type_is(e, "roughdielectric") || type_is(e, "thindielectric");
  if (glass) {
    m->type = HUSH_MAT_DIELECTRIC;
    m->two_sided = 0; /* refraction needs to know inside from outside */
    m->roughness = 0.0f;
    m->opacity = 1.0f; /* d 0 marks glass here, not a hole */
  } else if (e->pm >= 0.5f || type_is(e, "conductor") || type_is(e, "roughconductor")) {
    m->type = HUSH_MAT_CONDUCTOR;
  } else if (max3(e->ks) > 0.0f) {
    m->type = HUSH_MAT_PLASTIC;
    /* Mitsuba's phong has no Pr: a Blinn exponent Ns maps to a GGX alpha
     * of about sqrt(2 / (Ns + 2)) */
    if (!e->has_pr && type_is(e, "phong") && e->has_ns)
      m->roughness = fminf(sqrtf(2.0f / (fmaxf(e->ns, 0.0f) + 2.0f)), 1.0f);
  } else {
    m->type = HUSH_MAT_DIFFUSE;
  }
}

static hush_status load_materials(loader *l, const struct aiScene *ai, const mtl_file *mtl,
                                  const char *mtl_name) {
  hush_scene *s = l->scene;
  s->materials = calloc(ai->mNumMaterials ? ai->mNumMaterials : 1, sizeof *s->materials);
  if (!s->materials) return hush__fail(l->c.device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  s->material_count = ai->mNumMaterials ? ai->mNumMaterials : 1;
  for (uint32_t i = 0; i < s->material_count; i++) {
    hush_material *m = &s->materials[i];
    m->diffuse_texture = -1;
    m->alpha_texture = -1;
    m->diffuse[0] = m->diffuse[1] = m->diffuse[2] = 0.5f;
    m->ior = 1.5f;
    m->opacity = 1.0f;
    m->two_sided = s->two_sided;
    if (i >= ai->mNumMaterials) {
      snprintf(m->name, sizeof m->name, "default");
      continue;
    }
    struct aiString name;
    if (aiGetMaterialString(ai->mMaterials[i], AI_MATKEY_NAME, &name) == aiReturn_SUCCESS)
      copy_name(m->name, sizeof m->name, name.data);
    const mtl_entry *e = mtl_find(mtl, m->name);
    if (!e) {
      /* assimp's own default material, or a usemtl the MTL lacks: keep
       * assimp's diffuse colour */
      struct aiColor4D kd;
      if (aiGetMaterialColor(ai->mMaterials[i], AI_MATKEY_COLOR_DIFFUSE, &kd) == aiReturn_SUCCESS) {
        m->diffuse[0] = kd.r, m->diffuse[1] = kd.g, m->diffuse[2] = kd.b;
      }
      continue;
    }
    char bad[64];
    if (unknown_type(e, bad, sizeof bad))
      return hush__fail(l->c.device, HUSH_ERROR_UNSUPPORTED,
                        "%s: material '%s' (line %d): # mitsuba: type '%s' is not supported "
                        "(diffuse, roughdiffuse, plastic, roughplastic, phong, conductor, "
                        "roughconductor, dielectric, roughdielectric, thindielectric; wrappers "
                        "mask, twosided, bumpmap)",
                        mtl_name, e->name, e->line, bad);
    map_material(e, s->two_sided, m);
    char what[PATH_MAX_LEN + 256];
    if (e->map_kd[0]) {
      snprintf(what, sizeof what, "%s: material '%s' (line %d): map_Kd", mtl_name, e->name,
               e->line);
      const hush_status st = texture_index(l, e->map_kd, HUSH_TEXTURE_SRGB, what,
                                           &m->diffuse_texture);
      if (st != HUSH_OK) return st;
    }
    if (e->map_d[0] && m->type != HUSH_MAT_DIELECTRIC) {
      snprintf(what, sizeof what, "%s: material '%s' (line %d): map_d", mtl_name, e->name, e->line);
      const hush_status st = texture_index(l, e->map_d, HUSH_TEXTURE_ALPHA, what,
                                           &m->alpha_texture);
      if (st != HUSH_OK) return st;
    }
  }
  return HUSH_OK;
}

/* ------------------------------------------------------------------------ */
/* Geometry                                                                 */
/* ------------------------------------------------------------------------ */

static int emissive(const hush_material *m) {
  return m->emission[0] > 0.0f || m->emission[1] > 0.0f || m->emission[2] > 0.0f;
}

static int usable_triangle(const float *pos, const uint32_t ix[3]) {
  const float *a = pos + 3 * (size_t)ix[0], *b = pos + 3 * (size_t)ix[1],
              *c = pos + 3 * (size_t)ix[2];
  for (int k = 0; k < 3; k++)
    if (!isfinite(a[k]) || !isfinite(b[k]) || !isfinite(c[k])) return 0;
  const hush_vec3 e1 = hush_v3(b[0] - a[0], b[1] - a[1], b[2] - a[2]);
  const hush_vec3 e2 = hush_v3(c[0] - a[0], c[1] - a[1], c[2] - a[2]);
  const float area2 = hush_v3_length(hush_v3_cross(e1, e2));
  return isfinite(area2) && area2 > 0.0f;
}

/* Copies every triangle mesh of the import; one object per mesh. Counts the
 * triangles of the file (what the manifest counts) in *file_triangles and
 * *file_emissive, skipped ones included. */
static hush_status load_geometry(loader *l, const struct aiScene *ai, uint32_t *file_triangles,
                                 uint32_t *file_emissive) {
  hush_scene *s = l->scene;
  uint64_t nv = 0, nt = 0;
  int any_normals = 0, any_uvs = 0;
  for (uint32_t i = 0; i < ai->mNumMeshes; i++) {
    const struct aiMesh *mesh = ai->mMeshes[i];
    if (!(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    nv += mesh->mNumVertices;
    nt += mesh->mNumFaces;
    any_normals |= mesh->mNormals != NULL;
    any_uvs |= mesh->mTextureCoords[0] != NULL;
  }
  if (nv > UINT32_MAX / 4 || nt > UINT32_MAX / 4)
    return hush__fail(l->c.device, HUSH_ERROR_UNSUPPORTED, "%s: mesh too large", l->c.file);
  s->positions = malloc((nv ? nv : 1) * 3 * sizeof(float));
  s->normals = any_normals ? calloc((nv ? nv : 1) * 3, sizeof(float)) : NULL;
  s->uvs = any_uvs ? calloc((nv ? nv : 1) * 2, sizeof(float)) : NULL;
  s->indices = malloc((nt ? nt : 1) * 3 * sizeof(uint32_t));
  s->triangle_material = malloc((nt ? nt : 1) * sizeof(uint32_t));
  s->triangle_object = malloc((nt ? nt : 1) * sizeof(uint32_t));
  s->objects = calloc(ai->mNumMeshes ? ai->mNumMeshes : 1, sizeof *s->objects);
  if (!s->positions || (any_normals && !s->normals) || (any_uvs && !s->uvs) || !s->indices ||
      !s->triangle_material || !s->triangle_object || !s->objects)
    return hush__fail(l->c.device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory for the mesh");

  *file_triangles = 0;
  *file_emissive = 0;
  for (uint32_t i = 0; i < ai->mNumMeshes; i++) {
    const struct aiMesh *mesh = ai->mMeshes[i];
    if (!(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    const uint32_t base = s->vertex_count;
    const uint32_t material = mesh->mMaterialIndex < s->material_count ? mesh->mMaterialIndex : 0;
    for (uint32_t v = 0; v < mesh->mNumVertices; v++) {
      float *p = s->positions + 3 * (size_t)(base + v);
      p[0] = mesh->mVertices[v].x, p[1] = mesh->mVertices[v].y, p[2] = mesh->mVertices[v].z;
      if (mesh->mNormals) {
        float *n = s->normals + 3 * (size_t)(base + v);
        n[0] = mesh->mNormals[v].x, n[1] = mesh->mNormals[v].y, n[2] = mesh->mNormals[v].z;
      }
      if (mesh->mTextureCoords[0]) {
        float *t = s->uvs + 2 * (size_t)(base + v);
        t[0] = mesh->mTextureCoords[0][v].x, t[1] = mesh->mTextureCoords[0][v].y;
      }
    }
    s->vertex_count += mesh->mNumVertices;
    hush_object *obj = &s->objects[s->object_count];
    copy_name(obj->name, sizeof obj->name, mesh->mName.length ? mesh->mName.data : "mesh");
    obj->first_triangle = s->triangle_count;
    for (uint32_t f = 0; f < mesh->mNumFaces; f++) {
      const struct aiFace *face = &mesh->mFaces[f];
      if (face->mNumIndices != 3) continue; /* points and lines of a mixed mesh */
      (*file_triangles)++;
      const int lit = emissive(&s->materials[material]);
      *file_emissive += lit;
      uint32_t ix[3];
      int ok = 1;
      for (int k = 0; k < 3; k++) {
        ok &= face->mIndices[k] < mesh->mNumVertices;
        ix[k] = base + face->mIndices[k];
      }
      if (!ok || !usable_triangle(s->positions, ix)) {
        s->skipped_triangles++;
        continue;
      }
      const uint32_t t = s->triangle_count++;
      memcpy(s->indices + 3 * (size_t)t, ix, sizeof ix);
      s->triangle_material[t] = material;
      s->triangle_object[t] = s->object_count;
      s->emissive_triangles += lit;
    }
    obj->triangle_count = s->triangle_count - obj->first_triangle;
    if (obj->triangle_count) s->object_count++;
  }
  return HUSH_OK;
}

/* assimp reads files through these: every file as it is, except an MTL,
 * which it is told is not there. hush reads the MTL itself (parse_mtl),
 * and assimp's own MTL reader crashes on some malformed files (found by
 * fuzzing); without it assimp still names each mesh's material after its
 * usemtl, which is all load_materials asks of it. */
static size_t ai_read(struct aiFile *f, char *buf, size_t size, size_t count) {
  return fread(buf, size, count, (FILE *)f->UserData);
}

static size_t ai_write(struct aiFile *f, const char *buf, size_t size, size_t count) {
  (void)f, (void)buf, (void)size, (void)count;
  return 0;
}

static size_t ai_tell(struct aiFile *f) {
  const long at = ftell((FILE *)f->UserData);
  return at < 0 ? 0 : (size_t)at;
}

static size_t ai_size(struct aiFile *f) {
  struct stat st;
  if (fstat(fileno((FILE *)f->UserData), &st) != 0 || st.st_size < 0) return 0;
  return (size_t)st.st_size;
}

static enum aiReturn ai_seek(struct aiFile *f, size_t offset, enum aiOrigin origin) {
  const int whence =
      origin == aiOrigin_SET ? SEEK_SET : origin == aiOrigin_CUR ? SEEK_CUR : SEEK_END;
  if (offset > (size_t)LONG_MAX) return aiReturn_FAILURE;
  return fseek((FILE *)f->UserData, (long)offset, whence) == 0 ? aiReturn_SUCCESS
                                                                : aiReturn_FAILURE;
}

static void ai_flush(struct aiFile *f) { (void)f; }

static int is_mtl(const char *path) {
  const size_t n = strlen(path);
  return n >= 4 && path[n - 4] == '.' && tolower((unsigned char)path[n - 3]) == 'm' &&
         tolower((unsigned char)path[n - 2]) == 't' && tolower((unsigned char)path[n - 1]) == 'l';
}

static struct aiFile *ai_open(struct aiFileIO *io, const char *path, const char *mode) {
  (void)io;
  if (is_mtl(path) || strchr(mode, 'w') || strchr(mode, 'a')) return NULL;
  FILE *fp = fopen(path, "rb");
  if (!fp) return NULL;
  struct aiFile *f = calloc(1, sizeof *f);
  if (!f) {
    fclose(fp);
    return NULL;
  }
  f->ReadProc = ai_read;
  f->WriteProc = ai_write;
  f->TellProc = ai_tell;
  f->FileSizeProc = ai_size;
  f->SeekProc = ai_seek;
  f->FlushProc = ai_flush;
  f->UserData = (aiUserData)fp;
  return f;
}

static void ai_close(struct aiFileIO *io, struct aiFile *f) {
  (void)io;
  if (!f) return;
  fclose((FILE *)f->UserData);
  free(f);
}

static hush_status load_mesh(loader *l, const char *rel) {
  hush_scene *s = l->scene;
  const ctx *c = &l->c;
  char obj_path[PATH_MAX_LEN];
  hush_status st = join_path(c, s->dir, rel, "mesh", obj_path);
  if (st != HUSH_OK) return st;
  if (!is_file(obj_path))
    return hush__fail(c->device, HUSH_ERROR_NOT_FOUND, "%s: mesh: '%s' not found", c->file,
                      obj_path);

  /* our own reading of the MTL (see the top of the file) */
  mtl_file mtl = {NULL, 0};
  char mtl_rel[PATH_MAX_LEN], mtl_path[PATH_MAX_LEN] = "";
  if (find_mtllib(obj_path, mtl_rel)) {
    const ctx oc = {c->device, obj_path};
    st = join_path(&oc, s->dir, mtl_rel, "mtllib", mtl_path);
    if (st != HUSH_OK) return st;
    if (!is_file(mtl_path))
      return hush__fail(c->device, HUSH_ERROR_NOT_FOUND, "%s: mtllib: '%s' not found", obj_path,
                        mtl_path);
    st = parse_mtl(c, mtl_path, &mtl);
    if (st != HUSH_OK) return st;
  }

  const double t0 = hush__now_ms();
  /* No GenNormals: the OBJ's own normals are kept; meshes without normals
   * get the geometric normal at shading time. JoinIdenticalVertices works
   * within one mesh, and assimp's OBJ importer makes a mesh per material,
   * so vertices are never shared across materials. */
  struct aiFileIO io = {ai_open, ai_close, NULL};
  const struct aiScene *ai =
      aiImportFileEx(obj_path, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices, &io);
  if (!ai) {
    free(mtl.entries);
    return hush__fail(c->device, HUSH_ERROR_CORRUPT, "%s: mesh: cannot read '%s': %s", c->file,
                      obj_path, aiGetErrorString());
  }
  const double t1 = hush__now_ms();
  st = load_materials(l, ai, &mtl, mtl_path[0] ? mtl_path : obj_path);
  free(mtl.entries);
  const double t2 = hush__now_ms();
  uint32_t file_tris = 0, file_emissive = 0;
  if (st == HUSH_OK) st = load_geometry(l, ai, &file_tris, &file_emissive);
  aiReleaseImport(ai);
  if (st != HUSH_OK) return st;
  hush__log(c->device, 2, "%s: assimp %.0f ms, materials and textures %.0f ms, %u triangles",
            obj_path, t1 - t0, t2 - t1, s->triangle_count);
  l->file_triangles = file_tris;
  l->file_emissive = file_emissive;
  return HUSH_OK;
}

/* ------------------------------------------------------------------------ */
/* Lights                                                                   */
/* ------------------------------------------------------------------------ */

static hush_status parse_envmap(loader *l, const cJSON *light, const char *prefix) {
  hush_scene *s = l->scene;
  const ctx *c = &l->c;
  char field[96];
  snprintf(field, sizeof field, "%s.file", prefix);
  const char *file = get_string(light, "file");
  if (!file) return bad_field(c, field, "missing or not a string");
  char what[PATH_MAX_LEN + 128];
  snprintf(what, sizeof what, "%s: %s", c->file, field);
  hush_status st = texture_index(l, file, HUSH_TEXTURE_LINEAR, what, &s->env.texture);
  if (st != HUSH_OK) return st;
  s->env.type = HUSH_ENV_MAP;
  hush_m4_identity(s->env.to_world);
  snprintf(field, sizeof field, "%s.to_world", prefix);
  const cJSON *m = cJSON_GetObjectItemCaseSensitive(light, "to_world");
  if (m) {
    /* JSON rows -> column-major: element (r, c) goes to [c * 4 + r] */
    if (!cJSON_IsArray(m) || cJSON_GetArraySize(m) != 4)
      return bad_field(c, field, "not a 4x4 matrix (four rows of four numbers)");
    for (int r = 0; r < 4; r++) {
      const cJSON *row = cJSON_GetArrayItem(m, r);
      if (!cJSON_IsArray(row) || cJSON_GetArraySize(row) != 4)
        return bad_field(c, field, "not a 4x4 matrix (four rows of four numbers)");
      for (int col = 0; col < 4; col++) {
        const cJSON *e = cJSON_GetArrayItem(row, col);
        if (!cJSON_IsNumber(e) || !isfinite(e->valuedouble))
          return bad_field(c, field, "holds something that is not a finite number");
        s->env.to_world[col * 4 + r] = (float)e->valuedouble;
      }
    }
  }
  snprintf(field, sizeof field, "%s.scale", prefix);
  double scale;
  st = get_number(c, light, "scale", field, 0, 1.0, &scale);
  if (st != HUSH_OK) return st;
  if (scale < 0.0) return bad_field(c, field, "must not be negative");
  s->env.scale = (float)scale;
  return HUSH_OK;
}

static hush_status parse_sunsky(loader *l, const cJSON *light, const char *prefix) {
  hush_environment *env = &l->scene->env;
  const ctx *c = &l->c;
  char field[96];
  snprintf(field, sizeof field, "%s.sun_direction", prefix);
  hush_status st = get_floats(c, light, "sun_direction", field, 3, env->sun_direction);
  if (st != HUSH_OK) return st;
  const hush_vec3 d = hush_v3(env->sun_direction[0], env->sun_direction[1], env->sun_direction[2]);
  const float len = hush_v3_length(d);
  if (!(len > 0.0f)) return bad_field(c, field, "is the zero vector");
  for (int k = 0; k < 3; k++) env->sun_direction[k] /= len;
  static const char *const keys[4] = {"turbidity", "sky_scale", "sun_scale", "sun_radius_scale"};
  static const double defaults[4] = {3.0, 1.0, 1.0, 1.0};
  float *dst[4] = {&env->turbidity, &env->sky_scale, &env->sun_scale, &env->sun_radius_scale};
  for (int k = 0; k < 4; k++) {
    snprintf(field, sizeof field, "%s.%s", prefix, keys[k]);
    double v;
    st = get_number(c, light, keys[k], field, 0, defaults[k], &v);
    if (st != HUSH_OK) return st;
    if (v < 0.0) return bad_field(c, field, "must not be negative");
    *dst[k] = (float)v;
  }
  env->type = HUSH_ENV_SUNSKY;
  env->scale = 1.0f;
  hush_m4_identity(env->to_world);
  return HUSH_OK;
}

static hush_status parse_constant(loader *l, const cJSON *light, const char *prefix) {
  char field[96];
  snprintf(field, sizeof field, "%s.radiance", prefix);
  hush_environment *env = &l->scene->env;
  const hush_status st = get_floats(&l->c, light, "radiance", field, 3, env->color);
  if (st != HUSH_OK) return st;
  env->type = HUSH_ENV_CONSTANT;
  env->scale = 1.0f;
  hush_m4_identity(env->to_world);
  return HUSH_OK;
}

static hush_status parse_sphere(loader *l, const cJSON *light, const char *prefix) {
  hush_scene *s = l->scene;
  hush_sphere_light *grown = realloc(s->spheres, (s->sphere_count + 1) * sizeof *grown);
  if (!grown) return hush__fail(l->c.device, HUSH_ERROR_OUT_OF_MEMORY, "out of memory");
  s->spheres = grown;
  hush_sphere_light *sp = &s->spheres[s->sphere_count];
  memset(sp, 0, sizeof *sp);
  sp->off_from_frame = -1;
  char field[96];
  snprintf(field, sizeof field, "%s.center", prefix);
  hush_status st = get_floats(&l->c, light, "center", field, 3, sp->center);
  if (st != HUSH_OK) return st;
  snprintf(field, sizeof field, "%s.radiance", prefix);
  st = get_floats(&l->c, light, "radiance", field, 3, sp->radiance);
  if (st != HUSH_OK) return st;
  snprintf(field, sizeof field, "%s.radius", prefix);
  double r;
  st = get_number(&l->c, light, "radius", field, 1, 0.0, &r);
  if (st != HUSH_OK) return st;
  if (!(r > 0.0)) return bad_field(&l->c, field, "must be positive");
  sp->radius = (float)r;
  s->sphere_count++;
  return HUSH_OK;
}

static hush_status parse_lights(loader *l, const cJSON *root) {
  const ctx *c = &l->c;
  const cJSON *lights = cJSON_GetObjectItemCaseSensitive(root, "lights");
  if (!lights) return HUSH_OK;
  if (!cJSON_IsArray(lights)) return bad_field(c, "lights", "not an array");
  int i = 0;
  const cJSON *light;
  cJSON_ArrayForEach(light, lights) {
    char prefix[48], field[64];
    snprintf(prefix, sizeof prefix, "lights[%d]", i);
    snprintf(field, sizeof field, "%s.type", prefix);
    if (!cJSON_IsObject(light)) return bad_field(c, prefix, "not an object");
    const char *type = get_string(light, "type");
    if (!type) return bad_field(c, field, "missing or not a string");
    const int env_light = !strcmp(type, "envmap") || !strcmp(type, "sunsky") ||
                          !strcmp(type, "constant");
    if (env_light && l->scene->env.type != HUSH_ENV_NONE)
      return hush__fail(c->device, HUSH_ERROR_UNSUPPORTED,
                        "%s: %s: only one envmap, sunsky or constant light is supported", c->file,
                        field);
    hush_status st;
    if (!strcmp(type, "envmap")) st = parse_envmap(l, light, prefix);
    else if (!strcmp(type, "sunsky")) st = parse_sunsky(l, light, prefix);
    else if (!strcmp(type, "constant")) st = parse_constant(l, light, prefix);
    else if (!strcmp(type, "sphere")) st = parse_sphere(l, light, prefix);
    else
      return hush__fail(c->device, HUSH_ERROR_UNSUPPORTED,
                        "%s: %s: unknown light type '%s' (envmap, sunsky, constant and sphere are "
                        "supported)", c->file, field, type);
    if (st != HUSH_OK) return st;
    i++;
  }
  return HUSH_OK;
}

/* ------------------------------------------------------------------------ */
/* The manifest                                                             */
/* ------------------------------------------------------------------------ */

static hush_status check_count(const loader *l, const cJSON *root, const char *key,
                               uint32_t loaded) {
  double want;
  const hush_status st = get_number(&l->c, root, key, key, 0, -1.0, &want);
  if (st != HUSH_OK || want < 0.0) return st;
  if (want != (double)loaded)
    return hush__fail(l->c.device, HUSH_ERROR_CORRUPT,
                      "%s: %s: the manifest says %.0f, the mesh has %u", l->c.file, key, want,
                      loaded);
  return HUSH_OK;
}

static hush_status parse_manifest(loader *l, const cJSON *root) {
  hush_scene *s = l->scene;
  const ctx *c = &l->c;
  const cJSON *format = cJSON_GetObjectItemCaseSensitive(root, "format");
  if (!format) return bad_field(c, "format", "missing (expected \"hush-scene/1\")");
  if (!cJSON_IsString(format) || strcmp(format->valuestring, "hush-scene/1") != 0)
    return hush__fail(c->device, HUSH_ERROR_UNSUPPORTED,
                      "%s: format: '%s' is not supported (hush-scene/1 is)", c->file,
                      cJSON_IsString(format) ? format->valuestring : "(not a string)");
  const char *name = get_string(root, "name");
  if (name) copy_name(s->name, sizeof s->name, name);
  const cJSON *two = cJSON_GetObjectItemCaseSensitive(root, "two_sided");
  if (two && !cJSON_IsBool(two)) return bad_field(c, "two_sided", "not true or false");
  s->two_sided = cJSON_IsTrue(two);
  const cJSON *two_e = cJSON_GetObjectItemCaseSensitive(root, "two_sided_emitters");
  if (two_e && !cJSON_IsBool(two_e))
    return bad_field(c, "two_sided_emitters", "not true or false");
  s->two_sided_emitters = cJSON_IsTrue(two_e);

  const cJSON *camera = cJSON_GetObjectItemCaseSensitive(root, "camera");
  if (!camera) return bad_field(c, "camera", "missing");
  hush_status st = parse_pose(c, camera, "camera", &s->camera);
  if (st == HUSH_OK) st = parse_fov_axis(c, camera, "camera.fov_axis", &s->camera_fov_axis_x);
  if (st == HUSH_OK) st = parse_resolution(c, root, "resolution", &s->width, &s->height);
  if (st != HUSH_OK) return st;
  if (s->width == 0) s->width = 1280, s->height = 720;

  st = parse_lights(l, root);
  if (st != HUSH_OK) return st;
  const cJSON *cam_path = cJSON_GetObjectItemCaseSensitive(root, "camera_path");
  if (cam_path) {
    if (!cJSON_IsString(cam_path)) return bad_field(c, "camera_path", "not a string");
    st = load_camera_path(c, s, cam_path->valuestring);
    if (st != HUSH_OK) return st;
  }
  const char *mesh = get_string(root, "mesh");
  if (!mesh) return bad_field(c, "mesh", "missing or not a string");
  st = load_mesh(l, mesh);
  if (st == HUSH_OK) st = check_count(l, root, "triangles", l->file_triangles);
  if (st == HUSH_OK) st = check_count(l, root, "emissive_triangles", l->file_emissive);
  return st;
}

/* The manifest path and the scene folder from a file or folder path. */
static hush_status resolve_paths(hush_device device, const char *path, hush_scene *scene,
                                 char json[PATH_MAX_LEN]) {
  int n;
  if (is_dir(path)) {
    n = snprintf(scene->dir, sizeof scene->dir, "%s", path);
    if (n > 0 && n < (int)sizeof scene->dir) {
      while (n > 1 && scene->dir[n - 1] == '/') scene->dir[--n] = '\0';
      n = snprintf(json, PATH_MAX_LEN, "%s/scene.json", scene->dir);
    }
  } else {
    n = snprintf(json, PATH_MAX_LEN, "%s", path);
    const char *slash = strrchr(path, '/');
    if (n > 0 && n < PATH_MAX_LEN)
      snprintf(scene->dir, sizeof scene->dir, "%.*s", slash ? (int)(slash - path) : 1,
               slash ? path : ".");
  }
  if (n < 0 || n >= PATH_MAX_LEN)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "scene path too long");
  if (!is_file(json))
    return hush__fail(device, HUSH_ERROR_NOT_FOUND, "%s: not found", json);
  return HUSH_OK;
}

/* The folder's own name, for a manifest without "name". */
static void default_name(hush_scene *s) {
  const char *slash = strrchr(s->dir, '/');
  copy_name(s->name, sizeof s->name, slash ? slash + 1 : s->dir);
}

hush_status hush__scene_load(hush_device device, const char *path, hush_scene *scene) {
  if (!scene) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "scene is NULL");
  memset(scene, 0, sizeof *scene);
  scene->env.texture = -1;
  if (!path || !*path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "scene path is NULL or empty");
  char json[PATH_MAX_LEN];
  hush_status st = resolve_paths(device, path, scene, json);
  if (st != HUSH_OK) {
    hush__scene_free(scene);
    return st;
  }
  default_name(scene);
  const double t0 = hush__now_ms();
  loader l;
  memset(&l, 0, sizeof l);
  l.c.device = device;
  l.c.file = json;
  l.scene = scene;
  cJSON *root;
  st = parse_json(&l.c, json, NULL, &root);
  if (st == HUSH_OK) {
    st = parse_manifest(&l, root);
    cJSON_Delete(root);
  }
  free(l.texture_kinds);
  free(l.texture_paths);
  if (st != HUSH_OK) {
    hush__scene_free(scene);
    return st;
  }
  if (scene->skipped_triangles)
    hush__log(device, 1, "%s: skipped %u degenerate or non-finite triangles", json,
              scene->skipped_triangles);
  hush__log(device, 1, "%s: %u triangles (%u emissive), %u materials, %u textures in %.0f ms",
            json, scene->triangle_count, scene->emissive_triangles, scene->material_count,
            scene->texture_count, hush__now_ms() - t0);
  return HUSH_OK;
}

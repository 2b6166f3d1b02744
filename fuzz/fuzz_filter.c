/*
 * fuzz_filter.c — libFuzzer target for the filter API: every filter class on
 * small frames of the synthetic scene (src/eval/synthetic.h) with the
 * layers it lacks made up (spp, emission, gradients, ...), under parameters,
 * image formats, strides, corrupted pixels and API misuse that the input
 * bytes choose. The input is decoded into a plan first; the plan then runs
 * twice, on a device with 1 thread and on one with 3.
 *
 * What must hold, whatever the input (else abort(), which libFuzzer reports):
 *   - every failing call leaves a non-empty message on the device;
 *   - a successful execute writes only finite outputs (the library promises
 *     an error for NaN/Inf input, or their replacement by 0: never a NaN
 *     image);
 *   - both runs give the same statuses and the same output bits (hush.h:
 *     outputs do not depend on the thread count), which also catches reads
 *     of memory the filter never wrote.
 * Crashes, leaks and undefined behaviour are the sanitizers' to report.
 */
#include "hush.h"
#include "fuzz_common.h"
#include "core/half.h"
#include "eval/synthetic.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_W 40
#define MAX_H 24
#define MAX_FRAMES 4
#define MAX_IMAGES 24
#define MAX_SETS 6

/* ---- the plan ------------------------------------------------------------ */

enum { CORRUPT_NONE, CORRUPT_NAN, CORRUPT_INF, CORRUPT_NEGATIVE, CORRUPT_HUGE, CORRUPT_LARGE,
       CORRUPT_TINY, CORRUPT_ZERO, CORRUPT_GARBAGE, CORRUPTS };

typedef struct image_plan {
  int bind;      /* 0: left unbound */
  int half;      /* HALF formats instead of FLOAT */
  int extra;     /* channels beyond the class's (inputs only) */
  int pad_px;    /* floats or halves of padding after each pixel */
  int pad_row;   /* pixels of padding after each row */
  int corrupt;   /* CORRUPT_* (inputs only) */
  uint32_t seed; /* where the corrupted pixels are */
} image_plan;

typedef struct set_plan {
  int param, how, frame; /* frame: before which execute (0: before commit) */
} set_plan;

typedef struct plan {
  const hush_filter_class_info *cls;
  uint32_t width, height, frames, frame_step;
  hush_synth_params synth;
  image_plan image[MAX_IMAGES];
  set_plan set[MAX_SETS];
  int sets;
  int vectors;                 /* HUSH_MOTION_VECTORS */
  unsigned reset_mask;         /* frames executed with HUSH_HISTORY_RESET */
  unsigned null_info_mask;     /* frames executed with info == NULL */
  int info_size;               /* 0: full; else a made-up size */
  int misuse, misuse_frame;    /* one misuse of the API before that frame */
  int misuse_image;
  float jitter;
} plan;

static void decode(fuzz_bytes *b, plan *p) {
  memset(p, 0, sizeof *p);
  const uint32_t count = hush_filter_class_count();
  p->cls = hush_filter_class_at(fuzz_u8(b) % count);
  p->width = 1 + fuzz_u8(b) % MAX_W;
  p->height = 1 + fuzz_u8(b) % MAX_H;
  p->frames = 1 + fuzz_u8(b) % MAX_FRAMES;
  p->frame_step = 1 + fuzz_u8(b) % 8;
  hush__synth_defaults(&p->synth);
  p->synth.width = p->width;
  p->synth.height = p->height;
  p->synth.seed = fuzz_u8(b);
  p->synth.camera_move = (int)(fuzz_u8(b) % 3);
  p->synth.moving_object = (int)(fuzz_u8(b) & 1);
  p->vectors = (int)(fuzz_u8(b) & 1);
  p->reset_mask = fuzz_u8(b) & 0x0e & (unsigned)fuzz_u8(b);
  p->null_info_mask = fuzz_u8(b) & 0x0f & (unsigned)fuzz_u8(b) & (unsigned)fuzz_u8(b);
  p->info_size = fuzz_u8(b) < 16 ? (int)fuzz_u8(b) * 8 : 0;
  p->jitter = (float)((int)fuzz_u8(b) - 128) / 256.0f;
  const unsigned m = fuzz_u8(b);
  p->misuse = m < 200 ? 0 : (int)(m - 199);
  p->misuse_frame = (int)(fuzz_u8(b) % (p->frames + 1));
  p->misuse_image = (int)fuzz_u8(b);
  const uint32_t nimages =
      p->cls->image_count < MAX_IMAGES ? p->cls->image_count : MAX_IMAGES;
  for (uint32_t i = 0; i < nimages; i++) {
    const hush_image_info *ii = &p->cls->images[i];
    image_plan *q = &p->image[i];
    const unsigned f = fuzz_u8(b);
    /* required images are bound unless the byte says otherwise (rarely) */
    q->bind = ii->required ? f != 255 : (f & 3) != 0;
    q->half = (f >> 2) & 1;
    q->extra = ii->role == HUSH_IMAGE_INPUT ? (int)((f >> 3) & 1) : 0;
    q->pad_px = (f >> 4) & 1;
    q->pad_row = (int)((f >> 5) & 3);
    const unsigned c = fuzz_u8(b);
    q->corrupt = ii->role == HUSH_IMAGE_INPUT && c >= 192 ? (int)(1 + c % (CORRUPTS - 1)) : 0;
    q->seed = fuzz_u32(b);
  }
  p->sets = (int)(fuzz_u8(b) % (MAX_SETS + 1));
  for (int i = 0; i < p->sets; i++) {
    p->set[i].param = p->cls->param_count ? (int)(fuzz_u8(b) % p->cls->param_count) : 0;
    p->set[i].how = (int)fuzz_u8(b);
    p->set[i].frame = (int)(fuzz_u8(b) % (p->frames + 1));
  }
}

/* ---- frames ------------------------------------------------------------- */

/* The synthetic frame's layers a class's image is made from. */
typedef struct source {
  enum { SRC_LAYER, SRC_DIRECT, SRC_INDIRECT, SRC_EMISSION, SRC_SPP, SRC_VARIANCE,
         SRC_DEPTH_GRADIENT, SRC_GRADIENT, SRC_NONE } kind;
  hush_image_view layer, color, id; /* data NULL: absent */
} source;

static hush_image_view layer_of(hush_frame fr, const char *name) {
  hush_image_view v;
  if (hush_frame_get_layer(fr, name, &v) != HUSH_OK) memset(&v, 0, sizeof v);
  return v;
}

static source source_of(hush_frame fr, const char *name) {
  source s;
  memset(&s, 0, sizeof s);
  s.color = layer_of(fr, "color");
  s.id = layer_of(fr, "id");
  static const struct {
    const char *name;
    int kind;
  } made[] = {{"direct", SRC_DIRECT},     {"indirect", SRC_INDIRECT},
              {"emission", SRC_EMISSION}, {"spp", SRC_SPP},
              {"variance", SRC_VARIANCE}, {"depth_gradient", SRC_DEPTH_GRADIENT},
              {"gradient", SRC_GRADIENT}};
  s.kind = SRC_LAYER;
  for (size_t i = 0; i < sizeof made / sizeof made[0]; i++)
    if (!strcmp(name, made[i].name)) s.kind = made[i].kind;
  if (s.kind == SRC_LAYER) {
    s.layer = layer_of(fr, name);
    if (!s.layer.data) s.kind = SRC_NONE;
  }
  return s;
}

/* Value c of pixel (x, y) of a view, or 0. */
static float view_at(const hush_image_view *v, uint32_t x, uint32_t y, int c) {
  if (!v->data || c >= hush_format_channels(v->format)) return 0.0f;
  const char *row = (const char *)v->data + v->byte_offset + y * v->row_stride;
  return ((const float *)(const void *)(row + x * v->pixel_stride))[c];
}

/* What an image holds at (x, y), channel c, for frame k: the synthetic
 * frame's layer where it has one, else something plausible. */
static float value_of(const source *s, uint32_t x, uint32_t y, int c, uint32_t k, uint32_t seed) {
  const uint32_t i = (k * MAX_H + y) * MAX_W + x;
  const float r = fuzz_hash01(seed, i * 4 + (uint32_t)c);
  switch (s->kind) {
  case SRC_LAYER: return view_at(&s->layer, x, y, c);
  case SRC_DIRECT: return 0.6f * view_at(&s->color, x, y, c);
  case SRC_INDIRECT: return 0.4f * view_at(&s->color, x, y, c);
  case SRC_EMISSION: return view_at(&s->id, x, y, 0) == 5.0f ? view_at(&s->color, x, y, c) : 0.0f;
  case SRC_SPP: return r < 0.25f ? 0.0f : r < 0.9f ? 1.0f : 4.0f;
  case SRC_VARIANCE: return r * 0.5f;
  case SRC_DEPTH_GRADIENT: return (r - 0.5f) * 0.2f;
  case SRC_GRADIENT:
    /* per 3x3 stratum: current and previous luminance, landing index */
    if (c < 2) return r * 2.0f;
    return r < 0.2f ? -1.0f : (float)(int)(r * 9.0f);
  default: return 0.0f;
  }
}

static float corrupted(int how, float v, float r) {
  switch (how) {
  case CORRUPT_NAN: return NAN;
  case CORRUPT_INF: return r < 0.5f ? INFINITY : -INFINITY;
  case CORRUPT_NEGATIVE: return -1.0f - v;
  case CORRUPT_HUGE: return r < 0.5f ? 1e30f : -3e38f; /* beyond what filters accept */
  case CORRUPT_LARGE: return r < 0.5f ? 9e14f : -9e14f; /* just within it */
  case CORRUPT_TINY: return 1e-40f;
  case CORRUPT_ZERO: return 0.0f;
  case CORRUPT_GARBAGE: return (r - 0.5f) * 2e3f;
  default: return v;
  }
}

/* One bound image: its memory and view. */
typedef struct buffer {
  void *mem;
  hush_image_view view;
  int channels; /* the class's */
} buffer;

static int format_of(int channels, int half) {
  return half ? (int)HUSH_FORMAT_HALF + channels - 1 : (int)HUSH_FORMAT_FLOAT + channels - 1;
}

static void buffer_make(buffer *b, const image_plan *q, int channels, uint32_t w, uint32_t h) {
  const int ch = channels + q->extra > 4 ? 4 : channels + q->extra;
  const size_t comp = q->half ? 2 : 4;
  const size_t px = comp * (size_t)(ch + q->pad_px);
  const size_t row = px * (w + (size_t)q->pad_row);
  b->channels = channels;
  b->mem = calloc(row * h + 64, 1);
  if (!b->mem) abort();
  b->view.data = b->mem;
  b->view.format = (hush_format)format_of(ch, q->half);
  b->view.width = w;
  b->view.height = h;
  b->view.byte_offset = 0;
  b->view.pixel_stride = px;
  b->view.row_stride = row;
}

static void put(buffer *b, uint32_t x, uint32_t y, int c, float v) {
  char *p = (char *)b->mem + y * b->view.row_stride + x * b->view.pixel_stride;
  if (b->view.format >= HUSH_FORMAT_HALF)
    ((uint16_t *)p)[c] = hush__float_to_half(v);
  else
    ((float *)p)[c] = v;
}

static float get(const buffer *b, uint32_t x, uint32_t y, int c) {
  const char *p = (const char *)b->mem + y * b->view.row_stride + x * b->view.pixel_stride;
  if (b->view.format >= HUSH_FORMAT_HALF) return hush__half_to_float(((const uint16_t *)p)[c]);
  return ((const float *)p)[c];
}

static void fill_input(buffer *b, const image_plan *q, const char *name, hush_frame fr,
                       uint32_t k) {
  const int ch = hush_format_channels(b->view.format);
  const source src = source_of(fr, name);
  for (uint32_t y = 0; y < b->view.height; y++)
    for (uint32_t x = 0; x < b->view.width; x++)
      for (int c = 0; c < ch; c++) {
        float v = value_of(&src, x, y, c, k, q->seed);
        if (q->corrupt && fuzz_hash01(q->seed ^ 0x5bd1e995u, ((k * MAX_H + y) * MAX_W + x) * 4 +
                                                           (uint32_t)c) < 0.05f)
          v = corrupted(q->corrupt, v, fuzz_hash01(q->seed, x + y));
        put(b, x, y, c, v);
      }
}

/* The plan in words, printed before an abort. */
static void describe(const plan *p) {
  static const char *const corrupt[CORRUPTS] = {"", "nan", "inf", "negative", "huge",
                                                "large", "tiny", "zero", "garbage"};
  fprintf(stderr, "plan: %s %ux%u, %u frames (step %u), synth seed %u move %d object %d, "
                  "motion %s, reset 0x%x, null info 0x%x, info size %d, jitter %g, misuse %d "
                  "before frame %d (image %d)\n",
          p->cls->name, p->width, p->height, p->frames, p->frame_step, p->synth.seed,
          p->synth.camera_move, p->synth.moving_object, p->vectors ? "vectors" : "camera",
          p->reset_mask, p->null_info_mask, p->info_size, (double)p->jitter, p->misuse,
          p->misuse_frame, p->misuse_image);
  for (uint32_t i = 0; i < p->cls->image_count && i < MAX_IMAGES; i++) {
    const image_plan *q = &p->image[i];
    if (q->bind)
      fprintf(stderr, "  image %s: %s, +%d channels, pixel pad %d, row pad %d%s%s\n",
              p->cls->images[i].name, q->half ? "half" : "float", q->extra, q->pad_px,
              q->pad_row, q->corrupt ? ", corrupted: " : "", corrupt[q->corrupt]);
  }
  for (int i = 0; i < p->sets; i++) {
    const hush_param_info *pi = &p->cls->params[p->set[i].param];
    fprintf(stderr, "  set %s (how %d) before frame %d\n", pi->name, p->set[i].how,
            p->set[i].frame - 1);
  }
}

/* ---- one run ------------------------------------------------------------ */

/* What a run leaves to compare with the other run. */
typedef struct record {
  int status[64];
  int statuses;
  float *out; /* every output of every frame, in order */
  size_t count, cap;
} record;

static void note_status(record *r, hush_device dev, hush_status s) {
  if (s != HUSH_OK) {
    const char *msg = NULL;
    hush_status e = hush_device_get_error(dev, &msg);
    if (e == HUSH_OK || !msg || !msg[0]) {
      fprintf(stderr, "fuzz_filter: status %s without a message\n", hush_status_name(s));
      abort();
    }
  }
  if (r->statuses < 64) r->status[r->statuses++] = (int)s;
}

static void note_value(record *r, float v) {
  if (r->count == r->cap) {
    r->cap = r->cap ? 2 * r->cap : 4096;
    r->out = realloc(r->out, r->cap * sizeof *r->out);
    if (!r->out) abort();
  }
  r->out[r->count++] = v;
}

static hush_status apply_set(hush_filter f, const hush_param_info *pi, int how) {
  const double lo = pi->min_value, hi = pi->max_value, d = pi->default_value;
  double v;
  switch (how % 8) {
  case 0: v = lo; break;
  case 1: v = hi; break;
  case 2: v = d; break;
  case 3: v = lo + (hi - lo) * (how / 8) / 31.0; break;
  case 4: v = hi + 1.0; break;          /* out of range */
  case 5: v = lo - 1.0; break;          /* out of range */
  case 6: return hush_filter_set_float(f, pi->name, NAN);
  default:
    if (pi->type == HUSH_PARAM_ENUM && pi->enum_names)
      return hush_filter_set_string(f, pi->name, pi->enum_names[(how / 8) % ((int)hi + 1)]);
    return hush_filter_set_string(f, pi->name, how & 8 ? "true" : "no-such-value");
  }
  if (pi->type == HUSH_PARAM_FLOAT) return hush_filter_set_float(f, pi->name, (float)v);
  if (pi->type == HUSH_PARAM_BOOL) return hush_filter_set_bool(f, pi->name, v != 0.0);
  if (v > 2e9) v = 2e9;
  if (v < -2e9) v = -2e9;
  return hush_filter_set_int(f, pi->name, (int)v);
}

static void run(const plan *p, int threads, record *rec) {
  char config[32];
  snprintf(config, sizeof config, "threads=%d", threads);
  hush_device dev = hush_device_new(config);
  if (!dev) abort();
  hush_filter f = hush_filter_new(dev, p->cls->name);
  if (!f) abort();
  const uint32_t W = p->width, H = p->height, n = p->cls->image_count;
  buffer buf[MAX_IMAGES];
  memset(buf, 0, sizeof buf);
  for (uint32_t i = 0; i < n && i < MAX_IMAGES; i++) {
    if (!p->image[i].bind) continue;
    buffer_make(&buf[i], &p->image[i], p->cls->images[i].channels, W, H);
    note_status(rec, dev, hush_filter_set_image(f, p->cls->images[i].name, &buf[i].view));
  }
  for (int s = 0; s < p->sets; s++)
    if (p->set[s].frame == 0 && p->cls->param_count)
      note_status(rec, dev, apply_set(f, &p->cls->params[p->set[s].param], p->set[s].how));
  note_status(rec, dev, hush_filter_commit(f));

  hush_camera prev_cam;
  memset(&prev_cam, 0, sizeof prev_cam);
  for (uint32_t k = 0; k < p->frames; k++) {
    const uint32_t frame_no = k * p->frame_step;
    hush_frame fr = NULL;
    hush_camera cam;
    if (hush__synth_frame(dev, &p->synth, frame_no, &fr, &cam) != HUSH_OK) abort();
    for (uint32_t i = 0; i < n && i < MAX_IMAGES; i++)
      if (buf[i].mem && p->cls->images[i].role == HUSH_IMAGE_INPUT)
        fill_input(&buf[i], &p->image[i], p->cls->images[i].name, fr, k);
    for (int s = 0; s < p->sets; s++)
      if (p->set[s].frame == (int)k + 1 && p->cls->param_count)
        note_status(rec, dev, apply_set(f, &p->cls->params[p->set[s].param], p->set[s].how));

    /* one misuse, then the filter must still work once it is undone */
    const uint32_t mi = n ? (uint32_t)p->misuse_image % n : 0;
    const char *mname = n ? p->cls->images[mi].name : "color";
    if (p->misuse && p->misuse_frame == (int)k) {
      hush_frame_info info;
      hush_frame_info_init(&info);
      if (p->misuse == 1) {
        note_status(rec, dev, hush_filter_unset_image(f, mname));
        note_status(rec, dev, hush_filter_execute(f, &info));
        if (buf[mi].mem) note_status(rec, dev, hush_filter_set_image(f, mname, &buf[mi].view));
      } else if (p->misuse == 2 && buf[mi].mem && W > 1) {
        hush_image_view smaller = buf[mi].view;
        smaller.width = W - 1;
        note_status(rec, dev, hush_filter_set_image(f, mname, &smaller));
        note_status(rec, dev, hush_filter_execute(f, &info));
        note_status(rec, dev, hush_filter_set_image(f, mname, &buf[mi].view));
        note_status(rec, dev, hush_filter_commit(f));
      } else if (p->misuse == 3) {
        note_status(rec, dev, hush_filter_set_image(f, "no-such-image", &buf[mi].view));
        note_status(rec, dev, hush_filter_set_float(f, "no-such-param", 1.0f));
      } else if (p->misuse == 4 && buf[mi].mem) {
        hush_image_view bad = buf[mi].view;
        bad.pixel_stride = 1; /* overlapping pixels */
        note_status(rec, dev, hush_filter_set_image(f, mname, &bad));
        note_status(rec, dev, hush_filter_set_image(f, mname, &buf[mi].view));
      } else if (p->misuse == 5) {
        info.view_to_clip[0] = NAN;
        note_status(rec, dev, hush_filter_execute(f, &info));
      } else if (p->misuse == 6) {
        info.view_to_clip[15] = 0.0f; /* a singular projection */
        info.view_to_clip[11] = 0.0f;
        note_status(rec, dev, hush_filter_execute(f, &info));
      } else if (p->misuse >= 7 && p->misuse <= 9 && buf[mi].mem) {
        hush_image_view bad = buf[mi].view;
        if (p->misuse == 7) bad.data = NULL;
        if (p->misuse == 8) bad.row_stride = bad.pixel_stride; /* rows overlap */
        if (p->misuse == 9) bad.format = (hush_format)99;
        note_status(rec, dev, hush_filter_set_image(f, mname, &bad));
        note_status(rec, dev, hush_filter_execute(f, &info));
        note_status(rec, dev, hush_filter_set_image(f, mname, &buf[mi].view));
        note_status(rec, dev, hush_filter_commit(f));
      } else if (p->misuse == 10 && buf[mi].mem) {
        /* every output on one input's memory: they overlap */
        for (uint32_t i = 0; i < n && i < MAX_IMAGES; i++)
          if (buf[i].mem && p->cls->images[i].role == HUSH_IMAGE_OUTPUT) {
            hush_image_view over = buf[i].view;
            over.data = buf[mi].mem;
            note_status(rec, dev, hush_filter_set_image(f, p->cls->images[i].name, &over));
          }
        note_status(rec, dev, hush_filter_commit(f));
        note_status(rec, dev, hush_filter_execute(f, &info));
        for (uint32_t i = 0; i < n && i < MAX_IMAGES; i++)
          if (buf[i].mem && p->cls->images[i].role == HUSH_IMAGE_OUTPUT)
            note_status(rec, dev, hush_filter_set_image(f, p->cls->images[i].name, &buf[i].view));
        note_status(rec, dev, hush_filter_commit(f));
      }
    }

    hush_frame_info info;
    hush_frame_info_init(&info);
    info.frame_index = frame_no;
    memcpy(info.world_to_view, cam.world_to_view, sizeof info.world_to_view);
    memcpy(info.view_to_clip, cam.view_to_clip, sizeof info.view_to_clip);
    memcpy(info.prev_world_to_view, k ? prev_cam.world_to_view : cam.world_to_view,
           sizeof info.prev_world_to_view);
    memcpy(info.prev_view_to_clip, k ? prev_cam.view_to_clip : cam.view_to_clip,
           sizeof info.prev_view_to_clip);
    info.jitter[0] = p->jitter;
    info.jitter[1] = -p->jitter;
    info.motion = p->vectors ? HUSH_MOTION_VECTORS : HUSH_MOTION_CAMERA;
    info.history = (p->reset_mask >> k) & 1 ? HUSH_HISTORY_RESET : HUSH_HISTORY_CONTINUE;
    if (p->info_size) info.size = (size_t)p->info_size;
    const hush_status s =
        hush_filter_execute(f, (p->null_info_mask >> k) & 1 ? NULL : &info);
    note_status(rec, dev, s);
    prev_cam = cam;
    hush_frame_release(fr);
    if (s != HUSH_OK) continue;
    for (uint32_t i = 0; i < n && i < MAX_IMAGES; i++) {
      if (!buf[i].mem || p->cls->images[i].role != HUSH_IMAGE_OUTPUT) continue;
      const int half = buf[i].view.format >= HUSH_FORMAT_HALF;
      for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++)
          for (int c = 0; c < buf[i].channels; c++) {
            const float v = get(&buf[i], x, y, c);
            /* a half output may overflow to Inf on values above 65504 */
            if (isnan(v) || (!half && isinf(v))) {
              fprintf(stderr, "fuzz_filter: %s wrote %g to '%s' at (%u, %u) channel %d, frame %u\n",
                      p->cls->name, (double)v, p->cls->images[i].name, x, y, c, k);
              describe(p);
              abort();
            }
            note_value(rec, v);
          }
    }
  }
  hush_filter_release(f);
  hush_device_release(dev);
  for (uint32_t i = 0; i < MAX_IMAGES; i++) free(buf[i].mem);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fuzz_bytes b = {data, size};
  plan p;
  decode(&b, &p);
  /* FUZZ_FILTER_DESCRIBE=1: the plan first (for a sanitizer's report) */
  const char *say = getenv("FUZZ_FILTER_DESCRIBE");
  if (say && say[0] == '1') describe(&p);
  record r1, r3;
  memset(&r1, 0, sizeof r1);
  memset(&r3, 0, sizeof r3);
  run(&p, 1, &r1);
  run(&p, 3, &r3);
  if (r1.statuses != r3.statuses ||
      memcmp(r1.status, r3.status, sizeof r1.status[0] * (size_t)r1.statuses)) {
    fprintf(stderr, "fuzz_filter: %s: statuses differ between 1 and 3 threads\n", p.cls->name);
    describe(&p);
    abort();
  }
  if (r1.count != r3.count || (r1.count && memcmp(r1.out, r3.out, r1.count * sizeof *r1.out))) {
    size_t i = 0;
    while (i < r1.count && i < r3.count && !memcmp(&r1.out[i], &r3.out[i], sizeof *r1.out)) i++;
    fprintf(stderr, "fuzz_filter: %s: outputs differ between 1 and 3 threads (value %zu of %zu: %.9g vs %.9g)\n",
            p.cls->name, i, r1.count, i < r1.count ? (double)r1.out[i] : 0.0,
            i < r3.count ? (double)r3.out[i] : 0.0);
    describe(&p);
    abort();
  }
  free(r1.out);
  free(r3.out);
  return 0;
}

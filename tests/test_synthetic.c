/*
 * test_synthetic.c — the synthetic sequence generator: reproducible for any
 * thread count, "ref" is the expectation of "color", the sky and guide
 * layers follow hush.h's conventions, and the motion vectors point where
 * the surface really was in the previous frame (checked against the
 * previous frame's own positions, not against the formula that made them).
 */
#include "hush.h"

#include "check.h"
#include "core/hmath.h"
#include "eval/synthetic.h"

#include <math.h>
#include <string.h>

static const float *layer(hush_frame f, const char *name, int *channels) {
  hush_image_view v;
  if (hush_frame_get_layer(f, name, &v) != HUSH_OK) return NULL;
  if (channels) *channels = hush_format_channels(v.format);
  return (const float *)((const char *)v.data + v.byte_offset);
}

static hush_frame make(hush_device dev, const hush_synth_params *p, uint32_t frame) {
  hush_frame f = NULL;
  const hush_status st = hush__synth_frame(dev, p, frame, &f, NULL);
  if (st != HUSH_OK) {
    const char *msg;
    hush_device_get_error(dev, &msg);
    fprintf(stderr, "synth frame %u: %s\n", frame, msg);
  }
  REQUIRE(st == HUSH_OK && f);
  return f;
}

static void test_layers_and_determinism(void) {
  hush_device one = hush_device_new("threads=1"), two = hush_device_new("threads=2");
  REQUIRE(one && two);
  hush_synth_params p;
  hush__synth_defaults(&p);
  p.width = 64;
  p.height = 40;
  hush_frame a = make(one, &p, 3), b = make(two, &p, 3);
  static const char *const names[] = {"color", "ref", "albedo", "normal", "position",
                                      "depth", "motion", "id"};
  static const int channels[] = {3, 3, 3, 3, 3, 1, 2, 1};
  for (int i = 0; i < 8; i++) {
    int ca = 0, cb = 0;
    const float *la = layer(a, names[i], &ca), *lb = layer(b, names[i], &cb);
    CHECK_MSG(la && lb && ca == channels[i] && cb == channels[i], "layer %s", names[i]);
    if (la && lb)
      CHECK_MSG(memcmp(la, lb, sizeof(float) * 64 * 40 * (size_t)ca) == 0,
                "layer %s differs between 1 and 2 threads", names[i]);
  }
  hush_frame_release(a);
  hush_frame_release(b);

  /* another seed changes the noise, not the reference */
  hush_synth_params q = p;
  q.seed = 99;
  hush_frame c = make(one, &p, 3), d = make(one, &q, 3);
  CHECK(memcmp(layer(c, "ref", NULL), layer(d, "ref", NULL), sizeof(float) * 64 * 40 * 3) == 0);
  CHECK(memcmp(layer(c, "color", NULL), layer(d, "color", NULL), sizeof(float) * 64 * 40 * 3) != 0);
  hush_frame_release(c);
  hush_frame_release(d);
  hush_device_release(one);
  hush_device_release(two);
}

static void test_conventions(void) {
  hush_device dev = hush_device_new("threads=2");
  hush_synth_params p;
  hush__synth_defaults(&p);
  p.width = 80;
  p.height = 48;
  hush_frame f = NULL;
  hush_camera cam, cam2;
  REQUIRE(hush__synth_frame(dev, &p, 5, &f, &cam) == HUSH_OK);
  hush__synth_camera(&p, 5, &cam2);
  CHECK(memcmp(&cam, &cam2, sizeof cam) == 0);
  const float *color = layer(f, "color", NULL), *ref = layer(f, "ref", NULL);
  const float *albedo = layer(f, "albedo", NULL), *normal = layer(f, "normal", NULL);
  const float *pos = layer(f, "position", NULL), *depth = layer(f, "depth", NULL);
  const float *id = layer(f, "id", NULL);
  int sky = 0, hits = 0, bad_sky = 0, bad_normal = 0, bad_depth = 0, bad_proj = 0, ids[8] = {0};
  for (uint32_t y = 0; y < p.height; y++)
    for (uint32_t x = 0; x < p.width; x++) {
      const size_t i = (size_t)y * p.width + x;
      if (id[i] == 0.0f) {
        sky++;
        if (depth[i] != 0.0f || normal[3 * i] != 0.0f || normal[3 * i + 1] != 0.0f ||
            albedo[3 * i] != 1.0f || color[3 * i] != ref[3 * i] || color[3 * i + 2] != ref[3 * i + 2])
          bad_sky++;
        continue;
      }
      hits++;
      ids[(int)id[i] & 7]++;
      const float nl = sqrtf(normal[3 * i] * normal[3 * i] + normal[3 * i + 1] * normal[3 * i + 1] +
                             normal[3 * i + 2] * normal[3 * i + 2]);
      if (fabsf(nl - 1.0f) > 1e-4f) bad_normal++;
      const hush_vec4 v = hush_m4_mul_v4(cam.world_to_view, pos[3 * i], pos[3 * i + 1], pos[3 * i + 2], 1.0f);
      if (!(depth[i] > 0.0f) || fabsf(depth[i] + v.z) > 1e-3f * depth[i]) bad_depth++;
      /* the position projects back to this pixel's centre (row 0 at the top) */
      const hush_vec4 c = hush_m4_mul_v4(cam.view_to_clip, v.x, v.y, v.z, v.w);
      const float px = (c.x / c.w + 1.0f) * 0.5f * (float)p.width;
      const float py = (1.0f - c.y / c.w) * 0.5f * (float)p.height;
      if (fabsf(px - ((float)x + 0.5f)) > 0.01f || fabsf(py - ((float)y + 0.5f)) > 0.01f) bad_proj++;
    }
  CHECK_MSG(sky > 0 && hits > sky, "sky %d, hits %d", sky, hits);
  for (int k = 1; k <= 5; k++) CHECK_MSG(ids[k] > 0, "no pixel with id %d", k);
  /* the sky is at the top: row 0 sees sky, the bottom row sees ground */
  CHECK(id[p.width / 2] == 0.0f);
  CHECK(id[(size_t)(p.height - 1) * p.width + p.width / 2] != 0.0f);
  CHECK_MSG(bad_sky == 0, "%d bad sky pixels", bad_sky);
  CHECK_MSG(bad_normal == 0, "%d normals not unit", bad_normal);
  CHECK_MSG(bad_depth == 0, "%d depths not -z_view", bad_depth);
  CHECK_MSG(bad_proj == 0, "%d positions not at their pixel centre", bad_proj);
  hush_frame_release(f);

  /* frame 0 has no previous frame: motion 0 */
  REQUIRE(hush__synth_frame(dev, &p, 0, &f, NULL) == HUSH_OK);
  const float *m0 = layer(f, "motion", NULL);
  int nonzero = 0;
  for (size_t i = 0; i < (size_t)p.width * p.height * 2; i++) nonzero += m0[i] != 0.0f;
  CHECK(nonzero == 0);
  hush_frame_release(f);

  /* noise 0: color is ref */
  p.noise = 0.0f;
  REQUIRE(hush__synth_frame(dev, &p, 2, &f, NULL) == HUSH_OK);
  CHECK(memcmp(layer(f, "color", NULL), layer(f, "ref", NULL), sizeof(float) * 80 * 48 * 3) == 0);
  hush_frame_release(f);

  /* bad parameters are reported */
  p.noise = 2.0f;
  CHECK(hush__synth_frame(dev, &p, 0, &f, NULL) == HUSH_ERROR_OUT_OF_RANGE && f == NULL);
  const char *msg = NULL;
  CHECK(hush_device_get_error(dev, &msg) != HUSH_OK && strstr(msg, "noise"));
  p.noise = 1.0f;
  p.width = 0;
  CHECK(hush__synth_frame(dev, &p, 0, &f, NULL) == HUSH_ERROR_INVALID_ARGUMENT);
  hush_device_get_error(dev, NULL);
  hush_device_release(dev);
}

/* The mean of "color" over many seeds converges to "ref". */
static void test_expectation(void) {
  hush_device dev = hush_device_new("threads=2");
  hush_synth_params p;
  hush__synth_defaults(&p);
  p.width = 48;
  p.height = 32;
  const size_t n = (size_t)p.width * p.height * 3;
  double *sum = calloc(n, sizeof *sum);
  REQUIRE(sum);
  const int seeds = 400;
  hush_frame f = NULL;
  for (int s = 0; s < seeds; s++) {
    p.seed = (uint32_t)s * 7919u + 1u;
    f = make(dev, &p, 4);
    const float *c = layer(f, "color", NULL);
    for (size_t i = 0; i < n; i++) sum[i] += c[i];
    hush_frame_release(f);
  }
  f = make(dev, &p, 4);
  const float *ref = layer(f, "ref", NULL);
  double err = 0.0, total = 0.0, worst = 0.0;
  for (size_t i = 0; i < n; i++) {
    const double mean = sum[i] / seeds;
    err += mean - ref[i];
    total += ref[i];
    /* per value: the factor's standard deviation is 1, so the mean of 400 is
     * within 5 sigma = 0.25 of ref relative to the largest sample scale */
    const double rel = fabs(mean - ref[i]) / (ref[i] + 0.05);
    worst = rel > worst ? rel : worst;
  }
  CHECK_MSG(fabs(err) / total < 0.01, "mean bias %.4f", err / total);
  CHECK_MSG(worst < 0.4, "worst relative error %.3f", worst);
  hush_frame_release(f);
  free(sum);
  hush_device_release(dev);
}

/*
 * Motion vectors: the point seen at pixel centre c in frame f was at
 * c + motion in frame f-1. Look there in frame f-1 and compare positions:
 * equal for static objects, shifted by the object's move for the moving
 * sphere. Occlusion and sub-pixel offsets make some pixels disagree; almost
 * all must agree.
 */
static void test_motion(int camera_move) {
  hush_device dev = hush_device_new("threads=2");
  hush_synth_params p;
  hush__synth_defaults(&p);
  p.width = 160;
  p.height = 96;
  p.camera_move = camera_move;
  const uint32_t frame = 6;
  hush_frame cur = make(dev, &p, frame), prev = make(dev, &p, frame - 1);
  const float *m = layer(cur, "motion", NULL), *pos = layer(cur, "position", NULL);
  const float *id = layer(cur, "id", NULL);
  const float *ppos = layer(prev, "position", NULL), *pid = layer(prev, "id", NULL);
  /* how far the moving sphere went: compare the two frames' centroids of id 5 */
  double c_now[3] = {0}, c_prev[3] = {0};
  int n_now = 0, n_prev = 0;
  for (size_t i = 0; i < (size_t)p.width * p.height; i++) {
    if (id[i] == 5.0f) {
      for (int k = 0; k < 3; k++) c_now[k] += pos[3 * i + k];
      n_now++;
    }
    if (pid[i] == 5.0f) {
      for (int k = 0; k < 3; k++) c_prev[k] += ppos[3 * i + k];
      n_prev++;
    }
  }
  REQUIRE(n_now > 20 && n_prev > 20);
  float delta[3];
  for (int k = 0; k < 3; k++) delta[k] = (float)(c_now[k] / n_now - c_prev[k] / n_prev);
  CHECK_MSG(fabsf(delta[0]) > 0.05f, "the sphere moved %.3f", (double)delta[0]);

  int checked = 0, agree = 0, moving_checked = 0, moving_agree = 0;
  for (uint32_t y = 0; y < p.height; y++)
    for (uint32_t x = 0; x < p.width; x++) {
      const size_t i = (size_t)y * p.width + x;
      if (id[i] == 0.0f) continue;
      const float qx = (float)x + 0.5f + m[2 * i], qy = (float)y + 0.5f + m[2 * i + 1];
      if (qx < 1.0f || qy < 1.0f || qx >= (float)p.width - 1.0f || qy >= (float)p.height - 1.0f)
        continue;
      const size_t j = (size_t)qy * p.width + (size_t)qx;
      if (pid[j] != id[i]) continue; /* disoccluded */
      const int moving = id[i] == 5.0f;
      float d2 = 0.0f;
      for (int k = 0; k < 3; k++) {
        const float expect = pos[3 * i + k] - (moving ? delta[k] : 0.0f);
        d2 += (ppos[3 * j + k] - expect) * (ppos[3 * j + k] - expect);
      }
      /* a pixel covers about depth * 0.0087 units at this size; allow a few */
      const float tol = 0.05f + 0.03f * (float)sqrt(pos[3 * i] * pos[3 * i] + pos[3 * i + 2] * pos[3 * i + 2]);
      const int ok = sqrtf(d2) < tol;
      checked++;
      agree += ok;
      moving_checked += moving;
      moving_agree += moving && ok;
    }
  printf("camera %d: motion agrees at %d of %d pixels (moving sphere %d of %d)\n", camera_move,
         agree, checked, moving_agree, moving_checked);
  CHECK_MSG(checked > (int)(p.width * p.height / 2), "only %d pixels checked", checked);
  CHECK_MSG(agree > 0.97 * checked, "camera %d: motion agrees at %d of %d pixels", camera_move,
            agree, checked);
  CHECK_MSG(moving_checked > 10 && moving_agree > 0.9 * moving_checked,
            "moving sphere: motion agrees at %d of %d pixels", moving_agree, moving_checked);
  hush_frame_release(cur);
  hush_frame_release(prev);
  hush_device_release(dev);
}

int main(void) {
  test_layers_and_determinism();
  test_conventions();
  test_expectation();
  test_motion(HUSH_SYNTH_ORBIT);
  test_motion(HUSH_SYNTH_DOLLY);
  test_motion(HUSH_SYNTH_STATIC);
  return check_summary();
}

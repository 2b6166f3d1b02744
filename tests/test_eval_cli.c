/*
 * test_eval_cli.c — `hush eval` end to end on tiny sequences: the files of
 * docs/eval.md (headers, one row per filter and frame, the baselines, a
 * summary table in which accumulation beats the noisy input), --frames,
 * references from a directory or from the "ref" layer giving the same
 * numbers, bad input (missing references, another frame count or size, an
 * unknown filter or parameter), a filter that fails on one frame (marked
 * failed, the others complete; --strict makes it an error), the render form
 * on builtin:cornell (deterministic), report.html, and `hush bench --scene`;
 * --gradients (only the input frames get the "gradient" layer) and the lag
 * on builtin:light-off (the event found at frame 8 where the light goes off,
 * the noisy input at the reference at once, accumulation trailing it).
 */
#include "check.h"

#include "hush.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#define WORK HUSH_BINARY_DIR "/test_eval_cli"

typedef struct result {
  int status;
  char out[16384];
  char err[16384];
} result;

static char text[1 << 16];

static const char *read_file(const char *path) {
  text[0] = '\0';
  FILE *f = fopen(path, "rb");
  if (!f) return text;
  const size_t n = fread(text, 1, sizeof text - 1, f);
  text[n] = '\0';
  fclose(f);
  return text;
}

static void run(result *r, const char *cmd, const char *args) {
  char line[4096];
  snprintf(line, sizeof line, "'%s' %s %s > '%s/stdout.txt' 2> '%s/stderr.txt'", HUSH_CLI, cmd,
           args, WORK, WORK);
  const int s = system(line);
  r->status = (s != -1 && WIFEXITED(s)) ? WEXITSTATUS(s) : -1;
  snprintf(r->out, sizeof r->out, "%s", read_file(WORK "/stdout.txt"));
  snprintf(r->err, sizeof r->err, "%s", read_file(WORK "/stderr.txt"));
}

static void expect(const char *args, int status, const char *needle) {
  result r;
  run(&r, "eval", args);
  CHECK_MSG(r.status == status, "hush eval %s: exit %d, expected %d (%s)", args, r.status, status,
            r.err);
  if (needle)
    CHECK_MSG(strstr(r.err, needle) != NULL, "hush eval %s: no '%s' in '%s'", args, needle, r.err);
}

static int file_exists(const char *path) {
  FILE *f = fopen(path, "rb");
  if (f) fclose(f);
  return f != NULL;
}

/* Rows of metrics.csv for one filter: count and mean RMSE (column 3). */
static int metric_rows(const char *dir, const char *filter, double *mean_rmse) {
  char path[512], prefix[64];
  snprintf(path, sizeof path, "%s/metrics.csv", dir);
  snprintf(prefix, sizeof prefix, "%s,", filter);
  const char *p = read_file(path);
  int n = 0;
  double sum = 0.0;
  for (const char *line = p; line && *line; line = strchr(line, '\n'), line = line ? line + 1 : NULL) {
    if (strncmp(line, prefix, strlen(prefix)) != 0) continue;
    const char *c = strchr(line + strlen(prefix), ',');
    sum += c ? atof(c + 1) : 0.0;
    n++;
  }
  *mean_rmse = n ? sum / n : 0.0;
  return n;
}

static int starts_with(const char *s, const char *prefix) {
  return strncmp(s, prefix, strlen(prefix)) == 0;
}

static void test_files(void) {
  expect("--seq " WORK "/s --filters accumulate --out " WORK "/r --quiet", 0, NULL);
  CHECK(starts_with(read_file(WORK "/r/metrics.csv"),
                    "filter,frame,rmse,rel_mse,psnr,ssim,temporal_error,ref_temporal_error,ms\n"));
  CHECK(strstr(text, "\nnoisy,0,") && strstr(text, "\naccumulate,3,"));
  /* frame 0 has no previous frame: empty temporal errors; noisy has no time */
  CHECK(strstr(text, "\nnoisy,1,") && !strstr(text, "\nnoisy,4,"));
  double noisy, acc;
  CHECK(metric_rows(WORK "/r", "noisy", &noisy) == 4);
  CHECK(metric_rows(WORK "/r", "accumulate", &acc) == 4);
  CHECK_MSG(acc < noisy, "mean RMSE: accumulate %g, noisy %g", acc, noisy);
  CHECK(starts_with(read_file(WORK "/r/timings.csv"), "filter,stage,median_ms,p5_ms,p95_ms\n"));
  CHECK(strstr(text, "\naccumulate,total,") != NULL);
  CHECK(strcmp(read_file(WORK "/r/status.csv"),
               "filter,status,message\nnoisy,ok,\"\"\naccumulate,ok,\"\"\n") == 0);
  read_file(WORK "/r/summary.md");
  CHECK(strstr(text, "| filter | RMSE |") && strstr(text, "| noisy |") &&
        strstr(text, "| accumulate |") && strstr(text, "| reference |"));
  read_file(WORK "/r/eval.json");
  CHECK(strstr(text, "\"frames\": [0, 4]") && strstr(text, "\"filters\": [\"noisy\", \"accumulate\"]"));
  CHECK(strstr(text, "\"width\": 32") && strstr(text, "\"command\": [\"hush\", \"eval\""));
  CHECK(file_exists(WORK "/r/frames/noisy/frame_0000.exr"));
  CHECK(file_exists(WORK "/r/frames/accumulate/frame_0003.exr"));
  CHECK(file_exists(WORK "/r/frames/reference/frame_0003.exr"));
  CHECK(file_exists(WORK "/r/report.html"));

  /* the summary table goes to stdout without --quiet */
  result r;
  run(&r, "eval", "--seq " WORK "/s --filters accumulate --frames 1:3 --out " WORK "/r2");
  CHECK(r.status == 0 && strstr(r.out, "| accumulate |") && strstr(r.err, "frame 2/2"));
  CHECK(metric_rows(WORK "/r2", "accumulate", &acc) == 2);
  read_file(WORK "/r2/metrics.csv");
  CHECK(strstr(text, "\naccumulate,1,") && strstr(text, "\naccumulate,2,"));
  CHECK(strstr(read_file(WORK "/r2/eval.json"), "\"frames\": [1, 3]") != NULL);
}

/* A reference directory gives the same numbers as the "ref" layer. */
static void test_ref_dir(void) {
  expect("--seq " WORK "/s --ref " WORK "/clean --filters accumulate --out " WORK "/rd --quiet", 0,
         NULL);
  char a[8192];
  snprintf(a, sizeof a, "%s", read_file(WORK "/r/metrics.csv"));
  read_file(WORK "/rd/metrics.csv");
  /* compare the noisy rows: no timings in them */
  const char *na = strstr(a, "\nnoisy,"), *nb = strstr(text, "\nnoisy,");
  const char *ea = strstr(a, "\naccumulate,"), *eb = strstr(text, "\naccumulate,");
  CHECK(na && nb && ea && eb && ea - na == eb - nb && memcmp(na, nb, (size_t)(ea - na)) == 0);
  CHECK(strstr(read_file(WORK "/rd/eval.json"), "\"ref_layer\": \"color\"") != NULL);
}

static void test_bad_input(void) {
  expect("--seq " WORK "/s --ref " WORK "/nope --out " WORK "/x", 1, "does not exist");
  expect("--seq " WORK "/nope --out " WORK "/x", 1, "does not exist");
  expect("--seq " WORK "/s --ref " WORK "/short --out " WORK "/x", 1, "has 3 frames");
  expect("--seq " WORK "/s --ref " WORK "/small --out " WORK "/x", 1, "is 16x12");
  expect("--seq " WORK "/s --filters accumulate,nosuch --out " WORK "/x", 1,
         "unknown filter 'nosuch'");
  expect("--seq " WORK "/s --set accumulate.nosuch=1 --out " WORK "/x", 1, "nosuch");
  expect("--seq " WORK "/s --set other.alpha=1 --out " WORK "/x", 1, "not one of the filters");
  expect("--seq " WORK "/s --set alpha=1 --out " WORK "/x", 2, "FILTER.KEY=VALUE");
  expect("--seq " WORK "/s --frames 9: --out " WORK "/x", 1, "has 4 frames");
  expect("--seq " WORK "/s --frames 1:3 --show 0 --no-video --out " WORK "/x", 1,
         "--show 0: frames 1 to 2");
  expect("--out " WORK "/x", 2, "--seq");
  expect("--seq " WORK "/s", 2, "--out");
  expect("--seq " WORK "/s --scene builtin:cornell --out " WORK "/x", 2, "either");
  /* rendered frames have no "ref" layer: the references must be named */
  expect("--seq " WORK "/rr/seq --out " WORK "/x", 1, "no 'ref' layer");
}

/* Frame 2 of a copy of the sequence loses the layers accumulate needs. */
static void make_broken(hush_device dev) {
  REQUIRE(system("rm -rf '" WORK "/broken' && cp -r '" WORK "/s' '" WORK "/broken'") == 0);
  hush_frame in = NULL;
  REQUIRE(hush_frame_read_exr(dev, WORK "/broken/frame_0002.exr", &in) == HUSH_OK);
  hush_frame out = hush_frame_new(dev, hush_frame_width(in), hush_frame_height(in));
  REQUIRE(out);
  const char *keep[] = {"color", "ref"};
  for (int i = 0; i < 2; i++) {
    hush_image_view src, dst;
    REQUIRE(hush_frame_get_layer(in, keep[i], &src) == HUSH_OK);
    REQUIRE(hush_frame_add_layer(out, keep[i], 3, &dst) == HUSH_OK);
    memcpy(dst.data, src.data, (size_t)src.width * src.height * 3 * sizeof(float));
  }
  REQUIRE(hush_frame_write_exr(out, WORK "/broken/frame_0002.exr", HUSH_EXR_FLOAT) == HUSH_OK);
  hush_frame_release(out);
  hush_frame_release(in);
}

static void test_failing_filter(hush_device dev) {
  make_broken(dev);
  result r;
  run(&r, "eval", "--seq " WORK "/broken --filters accumulate --out " WORK "/rb --quiet");
  CHECK_MSG(r.status == 0, "exit %d: %s", r.status, r.err);
  CHECK(strstr(r.err, "warning: filter 'accumulate' failed at frame 2") != NULL);
  read_file(WORK "/rb/status.csv");
  CHECK(strstr(text, "noisy,ok,") && strstr(text, "accumulate,failed,\"frame_0002.exr has no"));
  double m;
  CHECK(metric_rows(WORK "/rb", "noisy", &m) == 4);
  CHECK(metric_rows(WORK "/rb", "accumulate", &m) == 2);
  CHECK(strstr(read_file(WORK "/rb/summary.md"), "accumulate (failed)") != NULL);
  expect("--seq " WORK "/broken --filters accumulate --strict --out " WORK "/rb --quiet", 1,
         "failed at frame 2");
}

static void test_render_form(void) {
  const char *args = "--scene builtin:cornell --size 48x32 --frames 3 --ref-spp 8 "
                     "--filters accumulate --quiet --out ";
  char line[1024];
  snprintf(line, sizeof line, "%s%s", args, WORK "/rr");
  expect(line, 0, NULL);
  double noisy, acc;
  CHECK(metric_rows(WORK "/rr", "noisy", &noisy) == 3);
  CHECK(metric_rows(WORK "/rr", "accumulate", &acc) == 3);
  CHECK(file_exists(WORK "/rr/seq/cameras.json") && file_exists(WORK "/rr/ref/frame_0002.exr"));
  CHECK(strstr(read_file(WORK "/rr/eval.json"), "\"scene\": \"builtin:cornell\"") != NULL);
  /* deterministic: a second run gives the same metrics (times aside) */
  snprintf(line, sizeof line, "%s%s --threads 1", args, WORK "/rr2");
  expect(line, 0, NULL);
  char a[8192];
  snprintf(a, sizeof a, "%s", read_file(WORK "/rr/metrics.csv"));
  read_file(WORK "/rr2/metrics.csv");
  const char *ea = strstr(a, "\naccumulate,"), *eb = strstr(text, "\naccumulate,");
  CHECK(ea && eb && ea - a == eb - text && memcmp(a, text, (size_t)(ea - a)) == 0);
}

static int has_layer(hush_device dev, const char *path, const char *layer) {
  hush_frame f = NULL;
  if (hush_frame_read_exr(dev, path, &f) != HUSH_OK) return -1;
  hush_image_view v;
  const int has = hush_frame_get_layer(f, layer, &v) == HUSH_OK;
  if (!has) hush_device_get_error(dev, NULL);
  hush_frame_release(f);
  return has;
}

/* Field `column` (0 = the filter) of lag.csv's row for filter. */
static void lag_field(const char *dir, const char *filter, int column, char *out, size_t size) {
  char path[512], prefix[64];
  snprintf(path, sizeof path, "%s/lag.csv", dir);
  snprintf(prefix, sizeof prefix, "\n%s,", filter);
  const char *p = strstr(read_file(path), prefix);
  out[0] = '\0';
  if (!p) return;
  p++;
  for (int c = 0; c < column && p; c++) p = strchr(p, ',') ? strchr(p, ',') + 1 : NULL;
  if (!p) return;
  const size_t n = strcspn(p, ",\n");
  snprintf(out, size, "%.*s", (int)(n < size ? n : size - 1), p);
}

static void test_gradients_and_lag(hush_device dev) {
  const char *args = "--scene builtin:light-off --path static --size 48x27 --frames 12 "
                     "--ref-spp 8 --filters accumulate --no-video --quiet";
  char line[1024];
  snprintf(line, sizeof line, "%s --gradients --out %s", args, WORK "/lo");
  expect(line, 0, NULL);
  CHECK(has_layer(dev, WORK "/lo/seq/frame_0003.exr", "gradient") == 1);
  CHECK(has_layer(dev, WORK "/lo/ref/frame_0003.exr", "gradient") == 0);
  CHECK(strstr(read_file(WORK "/lo/eval.json"), "\"gradients\": true") != NULL);
  /* the frames of the render form above have none: no filter needs them */
  CHECK(has_layer(dev, WORK "/rr/seq/frame_0001.exr", "gradient") == 0);
  CHECK(strstr(read_file(WORK "/rr/eval.json"), "\"gradients\": false") != NULL);

  CHECK(starts_with(read_file(WORK "/lo/lag.csv"),
                    "filter,event_frame,region_pixels,event_lag,shift_lag,brightened_pixels,"
                    "darkened_pixels,event_lag_brightened,event_lag_darkened\n"));
  char field[64];
  lag_field(WORK "/lo", "accumulate", 1, field, sizeof field);
  CHECK_MSG(strcmp(field, "8") == 0, "event frame '%s', the light goes off at 8", field);
  lag_field(WORK "/lo", "noisy", 3, field, sizeof field);
  CHECK_MSG(strcmp(field, "0") == 0, "noisy event lag '%s'", field);
  lag_field(WORK "/lo", "accumulate", 3, field, sizeof field);
  CHECK_MSG(strcmp(field, "inf") == 0 || atoi(field) >= 2, "accumulate event lag '%s'", field);
  /* a light switched off only darkens: the darkened part is (nearly) all
   * of the region and the event lag is its lag */
  char region[64], dark[64], dark_lag[64];
  lag_field(WORK "/lo", "accumulate", 2, region, sizeof region);
  lag_field(WORK "/lo", "accumulate", 6, dark, sizeof dark);
  lag_field(WORK "/lo", "accumulate", 8, dark_lag, sizeof dark_lag);
  CHECK_MSG(atoi(dark) > 0 && atoi(dark) >= 0.95 * atoi(region), "darkened %s of %s", dark,
            region);
  CHECK_MSG(strcmp(dark_lag, field) == 0, "darkened lag %s, event lag %s", dark_lag, field);
  CHECK(starts_with(read_file(WORK "/lo/lag_series.csv"), "frame,part,reference,noisy,accumulate\n"));
  CHECK(strstr(text, "\n8,darkened,") && strstr(text, "\n11,brightened,"));
  /* a light that jumps: one event at 8 with both parts over 1% of the frame */
  expect("--scene builtin:light-jump --path static --size 48x27 --frames 10 --ref-spp 4 "
         "--filters accumulate --no-video --quiet --out " WORK "/lj", 0, NULL);
  char up[64], down[64];
  lag_field(WORK "/lj", "accumulate", 1, field, sizeof field);
  lag_field(WORK "/lj", "accumulate", 5, up, sizeof up);
  lag_field(WORK "/lj", "accumulate", 6, down, sizeof down);
  CHECK_MSG(strcmp(field, "8") == 0 && atoi(up) >= 13 && atoi(down) >= 13,
            "light-jump: event frame '%s', brightened %s, darkened %s of 1296", field, up, down);
  read_file(WORK "/lo/summary.md");
  CHECK(strstr(text, "## Lag") &&
        strstr(text, "| lag | event (frames) | brightened | darkened | shift (frames) |") &&
        strstr(text, "Event at frame 8"));
  CHECK(strstr(read_file(WORK "/lo/report.html"), ">Lag<") != NULL); /* summary.md's table */

  /* the same event named; bad ones */
  snprintf(line, sizeof line, "--seq %s --ref %s --filters accumulate --lag-frame 8 --no-video "
           "--quiet --out %s", WORK "/lo/seq", WORK "/lo/ref", WORK "/lo2");
  expect(line, 0, NULL);
  char a[4096];
  snprintf(a, sizeof a, "%s", read_file(WORK "/lo/lag.csv"));
  CHECK(strcmp(a, read_file(WORK "/lo2/lag.csv")) == 0);
  snprintf(line, sizeof line, "--seq %s --ref %s --lag-frame 0 --out %s", WORK "/lo/seq",
           WORK "/lo/ref", WORK "/x");
  expect(line, 1, "--lag-frame 0");
  snprintf(line, sizeof line, "--seq %s --ref %s --lag-frame 12 --out %s", WORK "/lo/seq",
           WORK "/lo/ref", WORK "/x");
  expect(line, 1, "frames 0 to 11");
  expect("--seq " WORK "/s --gradients --out " WORK "/x", 2, "--gradients goes with --scene");

  /* automatic: a filter that reads the gradients (here bmfr under a second
   * name with temporal_gradients on; asvgf requires them) */
  expect("--scene builtin:light-off --path static --size 48x27 --frames 3 --ref-spp 2 "
         "--filters bmfr,bmfr-tg=bmfr --set bmfr-tg.temporal_gradients=on --no-video --quiet "
         "--out " WORK "/tg", 0, NULL);
  CHECK(has_layer(dev, WORK "/tg/seq/frame_0001.exr", "gradient") == 1);
  read_file(WORK "/tg/status.csv");
  CHECK(strstr(text, "bmfr,ok,") && strstr(text, "bmfr-tg,ok,"));
  CHECK(strstr(read_file(WORK "/tg/eval.json"), "\"bmfr\", \"bmfr-tg\"") != NULL);
  expect("--scene builtin:light-off --path static --size 48x27 --frames 2 --ref-spp 2 "
         "--filters asvgf --no-video --quiet --out " WORK "/ta", 0, NULL);
  CHECK(has_layer(dev, WORK "/ta/seq/frame_0001.exr", "gradient") == 1);
  /* without them, temporal_gradients fails with the image named */
  expect("--seq " WORK "/rr/seq --ref " WORK "/rr/ref --filters bmfr "
         "--set bmfr.temporal_gradients=on --strict --no-video --quiet --out " WORK "/tgx", 1,
         "'gradient'");
  expect("--seq " WORK "/s --filters =bmfr --out " WORK "/x", 1, "NAME=FILTER");
  expect("--seq " WORK "/s --filters a/b=bmfr --out " WORK "/x", 1, "a name has");
}

static void test_bench_scene(void) {
  result r;
  run(&r, "bench", "--scene builtin:cornell --size 32x24 --frames 2 --warmup 1 --distinct 2 "
                   "--filters accumulate --threads 1");
  CHECK_MSG(r.status == 0, "exit %d: %s", r.status, r.err);
  CHECK(strstr(r.out, "total") != NULL);
  run(&r, "bench", "--path orbit");
  CHECK(r.status == 2 && strstr(r.err, "--scene"));
  /* psf replays the vertices the frames selected through the public API */
  run(&r, "bench", "--scene builtin:cornell --size 32x24 --frames 3 --warmup 1 --distinct 2 "
                   "--filters psf,accumulate --set scale=8 --set psf.vertex=2 --csv '" WORK "/psf.csv'");
  CHECK_MSG(r.status == 0, "exit %d: %s", r.status, r.err);
  const char *psf = strstr(r.out, "\npsf ");
  CHECK_MSG(psf && strstr(psf, " add ") && strstr(psf, " resolve ") && strstr(psf, " lookup "),
            "no psf stages in: %s", r.out);
  const char *med = strstr(r.out, "medians per frame: ");
  CHECK_MSG(med && atoi(med + strlen("medians per frame: ")) > 0, "no vertices: %s", r.out);
  CHECK(strstr(read_file(WORK "/psf.csv"), "\npsf,add,32,24,3,") != NULL);
  run(&r, "bench", "--filters psf --size 32x24");
  CHECK(r.status == 1 && strstr(r.err, "psf") && strstr(r.err, "--scene"));
  run(&r, "bench", "--scene builtin:cornell --size 32x24 --frames 2 --filters psf --set scale=0");
  CHECK(r.status == 1 && strstr(r.err, "scale"));
}

int main(void) {
  REQUIRE(system("rm -rf '" WORK "' && mkdir -p '" WORK "'") == 0);
  const char *synth[] = {
      "--out " WORK "/s --size 32x24 --frames 4 --quiet",
      "--out " WORK "/clean --size 32x24 --frames 4 --noise 0 --quiet",
      "--out " WORK "/short --size 32x24 --frames 3 --quiet",
      "--out " WORK "/small --size 16x12 --frames 4 --quiet",
  };
  for (int i = 0; i < 4; i++) {
    result r;
    run(&r, "synth", synth[i]);
    REQUIRE(r.status == 0);
  }
  hush_device dev = hush_device_new(NULL);
  REQUIRE(dev);
  test_files();
  test_ref_dir();
  test_render_form();
  test_bad_input();
  test_failing_filter(dev);
  test_gradients_and_lag(dev);
  test_bench_scene();
  hush_device_release(dev);
  return check_summary();
}

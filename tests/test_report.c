/*
 * test_report.c — the HTML report from a hand-made report directory: tiny
 * EXRs (noisy, reference, two filters, one of which failed after frame 1),
 * hand-written metrics.csv, timings.csv, summary.md, status.csv and
 * eval.json. report.html must name the filters, hold the summary and timing
 * tables, the SVG plots, the failed filter's message and, with PATH pointing
 * at an empty directory, say that ffmpeg is not installed; every picture it
 * refers to must exist. Malformed inputs give errors naming file and line.
 * The line-plot writer is checked on its own too (NaN gaps, log axis).
 */
#include "check.h"

#include "eval/report.h"
#include "eval/svg.h"
#include "io/atomic_file.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define WORK HUSH_BINARY_DIR "/test_report"
#define W 24
#define H 16
#define FIRST 2
#define LAST 6

static hush_device dev;

static void write_file(const char *dir, const char *name, const char *text) {
  char path[HUSH_PATH_MAX];
  snprintf(path, sizeof path, "%s/%s", dir, name);
  FILE *f = fopen(path, "wb");
  REQUIRE(f);
  fputs(text, f);
  fclose(f);
}

static char *read_file(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  const long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *text = malloc((size_t)n + 1);
  REQUIRE(text && fread(text, 1, (size_t)n, f) == (size_t)n);
  text[n] = '\0';
  fclose(f);
  return text;
}

static int exists(const char *path) {
  struct stat st;
  return stat(path, &st) == 0;
}

/* A frame whose colour is a gradient plus `noise` times a pixel hash. */
static void write_exr(const char *dir, const char *column, uint32_t frame, float noise) {
  char path[HUSH_PATH_MAX];
  snprintf(path, sizeof path, "%s/frames/%s", dir, column);
  REQUIRE(hush__make_dirs(dev, path) == HUSH_OK);
  snprintf(path, sizeof path, "%s/frames/%s/frame_%04u.exr", dir, column, frame);
  hush_frame f = hush_frame_new(dev, W, H);
  hush_image_view v;
  REQUIRE(hush_frame_add_layer(f, "color", 3, &v) == HUSH_OK);
  float *px = v.data;
  for (uint32_t y = 0; y < H; y++) {
    for (uint32_t x = 0; x < W; x++) {
      const uint32_t hash = (x * 73856093u) ^ (y * 19349663u) ^ (frame * 83492791u);
      const float n = noise * ((float)(hash % 1000) / 1000.0f - 0.5f);
      /* the noisy error is largest in the lower right quarter */
      const float boost = x >= W / 2 && y >= H / 2 ? 3.0f : 1.0f;
      for (int c = 0; c < 3; c++)
        px[(y * W + x) * 3 + c] = 0.1f + 0.6f * (float)x / W + 0.1f * c + n * boost;
    }
  }
  REQUIRE(hush_frame_write_exr(f, path, HUSH_EXR_HALF) == HUSH_OK);
  hush_frame_release(f);
}

static const char *const metrics_header =
    "filter,frame,rmse,rel_mse,psnr,ssim,temporal_error,ref_temporal_error,ms\n";

/* A complete report directory. */
static void make_report_dir(const char *dir) {
  char cmd[HUSH_PATH_MAX + 16];
  snprintf(cmd, sizeof cmd, "%s/img", dir);
  REQUIRE(hush__make_dirs(dev, dir) == HUSH_OK);
  for (uint32_t f = FIRST; f < LAST; f++) {
    write_exr(dir, "noisy", f, 0.8f);
    write_exr(dir, "reference", f, 0.0f);
    write_exr(dir, "accumulate", f, 0.2f);
    if (f < FIRST + 2) write_exr(dir, "svgf", f, 0.05f);
  }
  char metrics[4096];
  size_t len = (size_t)snprintf(metrics, sizeof metrics, "%s", metrics_header);
  for (uint32_t f = FIRST; f < LAST; f++) {
    len += (size_t)snprintf(metrics + len, sizeof metrics - len,
                            "noisy,%u,0.25,0.9,12.0,0.31,%s,%s,0\n"
                            "accumulate,%u,0.05,0.1,26.0,0.83,%s,%s,0.41\n",
                            f, f == FIRST ? "" : "0.2", f == FIRST ? "" : "0.004", f,
                            f == FIRST ? "" : "0.01", f == FIRST ? "" : "0.004");
    if (f < FIRST + 2)
      len += (size_t)snprintf(metrics + len, sizeof metrics - len,
                              "svgf,%u,0.02,0.03,nan,0.95,%s,0.004,1.7\n", f,
                              f == FIRST ? "" : "0.006");
  }
  write_file(dir, "metrics.csv", metrics);
  write_file(dir, "timings.csv",
             "filter,stage,median_ms,p5_ms,p95_ms\n"
             "accumulate,reproject,0.20,0.18,0.25\n"
             "accumulate,total,0.41,0.39,0.52\n"
             "svgf,atrous,1.1,1.0,1.4\n"
             "svgf,total,1.7,1.6,2.1\n");
  write_file(dir, "summary.md",
             "| filter | RMSE | SSIM | PSNR | temporal error | ms/frame |\n"
             "| --- | ---: | ---: | ---: | ---: | ---: |\n"
             "| noisy | 0.25 | 0.31 | 12.0 | 0.2 | 0 |\n"
             "| accumulate | 0.05 | 0.83 | 26.0 | 0.01 | 0.41 |\n"
             "| svgf (failed) | 0.02 | 0.95 | | 0.006 | 1.7 |\n"
             "\n"
             "SSIM on display luminance.\n");
  write_file(dir, "status.csv",
             "filter,status,message\n"
             "noisy,ok,\n"
             "accumulate,ok,\n"
             "svgf,failed,\"frame 4: input <color> has NaN at (3, 5), gave up\"\n");
  write_file(dir, "eval.json",
             "{\"seq\": \"seq/noisy\", \"ref\": \"seq/ref\", \"frames\": [2, 6], \"width\": 24,"
             " \"height\": 16, \"filters\": [\"accumulate\", \"svgf\"],"
             " \"command\": [\"hush\", \"eval\", \"--seq\", \"seq/noisy\", \"--out\", \"a b\"]}\n");
}

/* Every src="..." of the page names a file that exists (video.mp4 aside,
 * which needs ffmpeg). Returns how many were checked. */
static int check_images(const char *dir, const char *html) {
  int count = 0;
  for (const char *p = strstr(html, "src=\""); p; p = strstr(p + 1, "src=\"")) {
    const char *start = p + 5, *end = strchr(start, '"');
    REQUIRE(end);
    char path[HUSH_PATH_MAX];
    snprintf(path, sizeof path, "%s/%.*s", dir, (int)(end - start), start);
    if (strstr(path, "video.mp4")) continue;
    CHECK_MSG(exists(path), "%s", path);
    count++;
  }
  return count;
}

static void test_full_report(const char *empty_path) {
  const char *dir = WORK "/full";
  make_report_dir(dir);
  const char *saved = getenv("PATH");
  char *old_path = saved ? strdup(saved) : NULL;
  setenv("PATH", empty_path, 1);
  const hush_report_options opt = {NULL, 0, 0.0f, HUSH_TONEMAP_ACES, 1};
  const hush_status status = hush__report_write(dev, dir, &opt);
  if (old_path) setenv("PATH", old_path, 1);
  free(old_path);
  const char *message = "";
  hush_device_get_error(dev, &message);
  CHECK_MSG(status == HUSH_OK, "%s: %s", hush_status_name(status), message);

  char *html = read_file(WORK "/full/report.html");
  REQUIRE(html);
  CHECK(strstr(html, "<!DOCTYPE html>") != NULL);
  CHECK(strstr(html, "accumulate") != NULL);
  CHECK(strstr(html, "svgf") != NULL);
  CHECK(strstr(html, ">noisy<") != NULL);
  CHECK(strstr(html, ">reference<") != NULL);
  /* summary.md as a table, the timing table with its stages */
  CHECK(strstr(html, "<th>temporal error</th>") != NULL);
  CHECK(strstr(html, "<td>svgf (failed)</td>") != NULL);
  CHECK(strstr(html, "median ms") != NULL);
  CHECK(strstr(html, "atrous") != NULL && strstr(html, "reproject") != NULL);
  CHECK(strstr(html, "<td>1.700</td>") != NULL);
  /* four plots, the reference's temporal error dashed */
  int svgs = 0;
  for (const char *p = strstr(html, "<svg xmlns"); p; p = strstr(p + 1, "<svg xmlns")) svgs++;
  CHECK_MSG(svgs == 4, "%d plots", svgs);
  CHECK(strstr(html, "stroke-dasharray") != NULL);
  CHECK(strstr(html, "RMSE against the reference") != NULL);
  CHECK(strstr(html, "SSIM against the reference") != NULL);
  CHECK(strstr(html, "Temporal error") != NULL);
  /* the failed filter, its message escaped, and its missing frames */
  CHECK(strstr(html, "Failed filters") != NULL);
  CHECK(strstr(html, "frame 4: input &lt;color&gt; has NaN at (3, 5), gave up") != NULL);
  CHECK(strstr(html, "failed: frame 4") != NULL);
  CHECK(strstr(html, "ffmpeg is not installed") != NULL);
  CHECK(strstr(html, "&#39;a b&#39;") != NULL); /* the command, quoted */
  /* frames 2, 3 and 5 are shown (first, middle, last) */
  CHECK(strstr(html, "Frame 2<") && strstr(html, "Frame 3<") && strstr(html, "Frame 5<"));
  CHECK(!strstr(html, "Frame 4<"));
  CHECK(exists(WORK "/full/img/f0002_svgf.png"));
  CHECK(!exists(WORK "/full/img/f0005_svgf.png"));
  CHECK(exists(WORK "/full/img/f0005_accumulate_err.png"));
  CHECK(exists(WORK "/full/img/f0005_noisy_crop0.png"));
  CHECK(exists(WORK "/full/img/f0005_reference_crop1.png"));
  CHECK(!exists(WORK "/full/img/f0005_reference_err.png"));
  CHECK(!exists(WORK "/full/video.mp4"));
  const int images = check_images(dir, html);
  /* picture + 2 insets + heat map per filter column, no heat map for the
   * reference: frames 2 and 3 with svgf (3 * 4 + 3), frame 5 without (2 * 4 + 3) */
  CHECK_MSG(images == 2 * 15 + 11, "%d images", images);
  free(html);
}

/* The frames the caller asks for, and one outside the evaluated range. */
static void test_chosen_frames(void) {
  const char *dir = WORK "/full";
  const uint32_t frames[1] = {4};
  hush_report_options opt = {frames, 1, 1.0f, HUSH_TONEMAP_REINHARD, 0};
  CHECK(hush__report_write(dev, dir, &opt) == HUSH_OK);
  char *html = read_file(WORK "/full/report.html");
  REQUIRE(html);
  CHECK(strstr(html, "Frame 4<") && !strstr(html, "Frame 2<"));
  CHECK(strstr(html, "video: not requested") != NULL);
  CHECK(strstr(html, "+1 stops, reinhard") != NULL);
  CHECK(strstr(html, "failed: frame 4") != NULL); /* svgf has no frame 4 */
  free(html);

  const uint32_t outside[1] = {6};
  opt.frames = outside;
  CHECK(hush__report_write(dev, dir, &opt) == HUSH_ERROR_OUT_OF_RANGE);
  const char *message;
  hush_device_get_error(dev, &message);
  CHECK_MSG(strstr(message, "frame 6") != NULL, "%s", message);
}

/* A malformed file: the status, and a message naming the file and line. */
static void expect_error(const char *dir, hush_status expected, const char *file,
                         const char *line) {
  const hush_report_options opt = {NULL, 0, 0.0f, HUSH_TONEMAP_CLAMP, 0};
  const hush_status status = hush__report_write(dev, dir, &opt);
  const char *message = "";
  hush_device_get_error(dev, &message);
  CHECK_MSG(status == expected, "%s: %s", hush_status_name(status), message);
  CHECK_MSG(strstr(message, file) != NULL, "'%s' lacks '%s'", message, file);
  if (line) CHECK_MSG(strstr(message, line) != NULL, "'%s' lacks '%s'", message, line);
}

static void test_bad_input(void) {
  const char *dir = WORK "/bad";
  make_report_dir(dir);
  char text[1024];

  snprintf(text, sizeof text, "%snoisy,2,0.25,0.9,12,0.3,,,0\nnoisy,3,abc,0.9,12,0.3,,,0\n",
           metrics_header);
  write_file(dir, "metrics.csv", text);
  expect_error(dir, HUSH_ERROR_CORRUPT, "metrics.csv", "line 3");

  snprintf(text, sizeof text, "%snoisy,2,0.25,0.9,12,0.3,,,0\n\nnoisy,3,0.25,0.9\n",
           metrics_header);
  write_file(dir, "metrics.csv", text);
  expect_error(dir, HUSH_ERROR_CORRUPT, "metrics.csv", "line 4");

  write_file(dir, "metrics.csv", "filter,frame,rmse\nnoisy,2,0.1\n");
  expect_error(dir, HUSH_ERROR_CORRUPT, "metrics.csv", "no column 'rel_mse'");

  snprintf(text, sizeof text, "%snoisy,2,0.25,0.9,12,0.3,,,\"0\n", metrics_header);
  write_file(dir, "metrics.csv", text);
  expect_error(dir, HUSH_ERROR_CORRUPT, "metrics.csv", "line 2");

  snprintf(text, sizeof text, "%s../x,2,0.25,0.9,12,0.3,,,0\n", metrics_header);
  write_file(dir, "metrics.csv", text);
  expect_error(dir, HUSH_ERROR_CORRUPT, "metrics.csv", "line 2");

  snprintf(text, sizeof text, "%snoisy,2,0.25,0.9,12,0.3,,,0\n", metrics_header);
  write_file(dir, "metrics.csv", text);
  write_file(dir, "status.csv", "filter,status,message\nsvgf,crashed,x\n");
  expect_error(dir, HUSH_ERROR_CORRUPT, "status.csv", "line 2");

  write_file(dir, "status.csv", "filter,status,message\n");
  write_file(dir, "eval.json", "{\"seq\": \"s\", \"frames\": [2, 6]}");
  expect_error(dir, HUSH_ERROR_CORRUPT, "eval.json", "ref");
  write_file(dir, "eval.json", "not json");
  expect_error(dir, HUSH_ERROR_CORRUPT, "eval.json", NULL);
  remove(WORK "/bad/eval.json");
  expect_error(dir, HUSH_ERROR_NOT_FOUND, "eval.json", NULL);

  /* a missing reference frame is named */
  make_report_dir(dir);
  remove(WORK "/bad/frames/reference/frame_0005.exr");
  expect_error(dir, HUSH_ERROR_NOT_FOUND, "frames/reference/frame_0005.exr", NULL);
}

/* With ffmpeg installed, the video is made (skipped where it is not). */
static void test_video(void) {
  const char *path = getenv("PATH");
  if (!path || system("command -v ffmpeg >/dev/null 2>&1") != 0) {
    printf("ffmpeg not installed: video case skipped\n");
    return;
  }
  const hush_report_options opt = {NULL, 0, 0.0f, HUSH_TONEMAP_ACES, 1};
  CHECK(hush__report_write(dev, WORK "/full", &opt) == HUSH_OK);
  CHECK(exists(WORK "/full/video.mp4"));
  char *html = read_file(WORK "/full/report.html");
  REQUIRE(html);
  CHECK(strstr(html, "<video src=\"video.mp4\"") != NULL);
  free(html);
}

static void test_svg(void) {
  const double x[5] = {0, 1, 2, 3, 4};
  const double a[5] = {0.5, 0.2, NAN, 0.01, 0.02};
  const double b[5] = {1e-3, 2e-3, 2e-3, 1e-3, -1.0};
  const hush_svg_series series[2] = {{"noisy <a>", x, a, 5, "#888", 0}, {"ref", x, b, 5, "#000", 1}};
  hush_strbuf out = {0};
  const hush_svg_plot plot = {"RMSE", "frame", "RMSE", 600, 300, 1, series, 2};
  hush__svg_line_plot(&out, &plot);
  REQUIRE(!out.failed && out.data);
  CHECK(strncmp(out.data, "<svg", 4) == 0);
  CHECK(strstr(out.data, "</svg>") != NULL);
  CHECK(strstr(out.data, "noisy &lt;a&gt;") != NULL);
  CHECK(strstr(out.data, "(log scale)") != NULL);
  CHECK(strstr(out.data, ">0.001<") != NULL && strstr(out.data, ">1<") != NULL);
  CHECK(strstr(out.data, "nan") == NULL && strstr(out.data, "inf") == NULL);
  /* the NaN breaks the line: two pieces (M twice) in the first path */
  const char *d = strstr(out.data, " d=\"M");
  REQUIRE(d);
  const char *second = strchr(d + 5, 'M');
  CHECK(second && second < strstr(d, "\"/>"));
  hush__strbuf_free(&out);

  const hush_svg_plot empty = {"nothing", "frame", "y", 400, 200, 0, NULL, 0};
  hush__svg_line_plot(&out, &empty);
  CHECK(out.data && strstr(out.data, "no data") != NULL);
  hush__strbuf_free(&out);
}

int main(void) {
  dev = hush_device_new("threads=2");
  REQUIRE(dev);
  REQUIRE(system("rm -rf '" WORK "'") == 0);
  REQUIRE(hush__make_dirs(dev, WORK "/empty-path") == HUSH_OK);
  test_svg();
  test_full_report(WORK "/empty-path");
  test_chosen_frames();
  test_bad_input();
  test_video();
  hush_device_release(dev);
  return check_summary();
}

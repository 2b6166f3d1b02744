/*
 * test_cli.c — the `hush` command end to end: `hush filters` lists the
 * filters from the library's tables; `hush synth` + `hush denoise --filter
 * accumulate` runs and measurably reduces the error against the noise-free
 * reference; `hush convert` round-trips; and every bad input gives a
 * non-zero exit, one line on stderr naming the problem, and no temporary
 * files left in the output directory.
 */
#include "hush.h"

#include "check.h"
#include "eval/synthetic.h"
#include "io/sequence.h"

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#define WORK HUSH_BINARY_DIR "/test_cli"
#define SEQ WORK "/seq"
#define OUT WORK "/out"

/* The captured result of one command. */
typedef struct result {
  int status; /* exit status, or -1 if it did not exit normally */
  char out[65536];
  char err[4096];
} result;

static void read_file(const char *path, char *buf, size_t size) {
  buf[0] = '\0';
  FILE *f = fopen(path, "rb");
  if (!f) return;
  const size_t n = fread(buf, 1, size - 1, f);
  buf[n] = '\0';
  fclose(f);
}

/* Runs `hush ARGS` with stdout and stderr captured to files. */
static void hush(result *r, const char *args) {
  char cmd[4096];
  snprintf(cmd, sizeof cmd, "'%s' %s > '%s/stdout.txt' 2> '%s/stderr.txt'", HUSH_CLI, args, WORK,
           WORK);
  const int s = system(cmd);
  r->status = (s != -1 && WIFEXITED(s)) ? WEXITSTATUS(s) : -1;
  read_file(WORK "/stdout.txt", r->out, sizeof r->out);
  read_file(WORK "/stderr.txt", r->err, sizeof r->err);
}

static void sh(const char *cmd) {
  const int s = system(cmd);
  REQUIRE(s != -1 && WIFEXITED(s) && WEXITSTATUS(s) == 0);
}

static int count_lines(const char *s) {
  int n = 0;
  for (; *s; s++) n += *s == '\n';
  return n;
}

static int file_exists(const char *path) {
  struct stat sb;
  return stat(path, &sb) == 0;
}

/* Whether dir holds a leftover temporary file ("*.tmp-*"). */
static int has_tmp_files(const char *dir) {
  DIR *d = opendir(dir);
  if (!d) return 0;
  int found = 0;
  for (struct dirent *e; (e = readdir(d));)
    if (strstr(e->d_name, ".tmp-")) found = 1;
  closedir(d);
  return found;
}

/* A failing command: status `status`, exactly one line on stderr that
 * starts with "hush" and contains each of the given facts. */
#define CHECK_FAILS(r, expect_status, ...)                                                   \
  do {                                                                                       \
    const char *facts_[] = {__VA_ARGS__, NULL};                                              \
    CHECK_MSG((r)->status == (expect_status), "status %d, expected %d; stderr: %s",          \
              (r)->status, (expect_status), (r)->err);                                       \
    CHECK_MSG(count_lines((r)->err) == 1 && strncmp((r)->err, "hush", 4) == 0,              \
              "expected one 'hush ...' line on stderr, got: %s", (r)->err);                  \
    for (int k_ = 0; facts_[k_]; k_++)                                                       \
      CHECK_MSG(strstr((r)->err, facts_[k_]) != NULL, "'%s' not in: %s", facts_[k_], (r)->err); \
  } while (0)

/* ---- library helpers for making bad inputs ----------------------------- */

static void write_small_sequence(hush_device dev, const char *dir) {
  char cmd[1024];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  sh(cmd);
  hush_synth_params p;
  hush__synth_defaults(&p);
  p.width = 32;
  p.height = 24;
  p.frames = 4;
  REQUIRE(hush__synth_write_sequence(dev, &p, dir) == HUSH_OK);
}

/* Rewrites dir/file without one layer. */
static void drop_layer(hush_device dev, const char *path, const char *drop) {
  hush_frame in = NULL;
  REQUIRE(hush_frame_read_exr(dev, path, &in) == HUSH_OK);
  hush_frame out = hush_frame_new(dev, hush_frame_width(in), hush_frame_height(in));
  REQUIRE(out);
  for (uint32_t i = 0; i < hush_frame_layer_count(in); i++) {
    const char *name = hush_frame_layer_name(in, i);
    if (strcmp(name, drop) == 0) continue;
    hush_image_view from, to;
    REQUIRE(hush_frame_get_layer(in, name, &from) == HUSH_OK);
    const int channels = hush_format_channels(from.format);
    REQUIRE(hush_frame_add_layer(out, name, channels, &to) == HUSH_OK);
    memcpy(to.data, from.data, sizeof(float) * channels * from.width * from.height);
  }
  hush_frame_release(in);
  REQUIRE(hush_frame_write_exr(out, path, HUSH_EXR_FLOAT) == HUSH_OK);
  hush_frame_release(out);
}

/* Sum of squared differences between two 3-channel layers, and the count. */
static void sq_error(hush_device dev, const char *a_path, const char *a_layer, const char *b_path,
                     const char *b_layer, double *sum, double *count) {
  hush_frame a = NULL, b = NULL;
  REQUIRE(hush_frame_read_exr(dev, a_path, &a) == HUSH_OK);
  REQUIRE(hush_frame_read_exr(dev, b_path, &b) == HUSH_OK);
  hush_image_view va, vb;
  REQUIRE(hush_frame_get_layer(a, a_layer, &va) == HUSH_OK);
  REQUIRE(hush_frame_get_layer(b, b_layer, &vb) == HUSH_OK);
  REQUIRE(va.width == vb.width && va.height == vb.height);
  REQUIRE(hush_format_channels(va.format) == 3 && hush_format_channels(vb.format) == 3);
  const float *pa = va.data, *pb = vb.data;
  for (size_t i = 0; i < (size_t)va.width * va.height * 3; i++) {
    const double d = (double)pa[i] - (double)pb[i];
    *sum += d * d;
  }
  *count += (double)va.width * va.height * 3;
  hush_frame_release(a);
  hush_frame_release(b);
}

/* ---- tests -------------------------------------------------------------- */

static void test_top_level(void) {
  result r;
  hush(&r, "--version");
  CHECK(r.status == 0 && strstr(r.out, hush_version()));
  hush(&r, "--help");
  CHECK(r.status == 0 && strstr(r.out, "denoise") && strstr(r.out, "synth") &&
        strstr(r.out, "convert") && strstr(r.out, "filters"));
  static const char *const cmds[] = {"filters", "denoise", "convert", "synth"};
  for (int i = 0; i < 4; i++) {
    char args[64];
    snprintf(args, sizeof args, "%s --help", cmds[i]);
    hush(&r, args);
    CHECK_MSG(r.status == 0 && strstr(r.out, "usage: hush") && strstr(r.out, cmds[i]),
              "hush %s --help", cmds[i]);
  }
  hush(&r, "frobnicate");
  CHECK_FAILS(&r, 2, "frobnicate");
  hush(&r, "");
  CHECK(r.status == 2);
}

static void test_filters(void) {
  result r;
  hush(&r, "filters");
  CHECK(r.status == 0);
  for (uint32_t i = 0; i < hush_filter_class_count(); i++) {
    const hush_filter_class_info *c = hush_filter_class_at(i);
    CHECK_MSG(strstr(r.out, c->name) != NULL, "filter %s not listed", c->name);
    for (uint32_t k = 0; k < c->param_count; k++)
      CHECK_MSG(strstr(r.out, c->params[k].name) != NULL, "parameter %s not listed",
                c->params[k].name);
    for (uint32_t k = 0; k < c->image_count; k++)
      CHECK_MSG(strstr(r.out, c->images[k].name) != NULL, "image %s not listed", c->images[k].name);
  }
  CHECK(strstr(r.out, "accumulate") != NULL);

  hush(&r, "filters accumulate --markdown");
  const hush_filter_class_info *acc = hush_filter_class_find("accumulate");
  REQUIRE(acc);
  char row[128];
  snprintf(row, sizeof row, "| `%s` |", acc->params[acc->param_count - 1].name);
  CHECK_MSG(r.status == 0 && strstr(r.out, row) && strstr(r.out, "|---|"), "markdown: %s", r.out);

  hush(&r, "filters nosuch");
  CHECK_FAILS(&r, 1, "nosuch", "accumulate");
  hush(&r, "filters --bogus");
  CHECK_FAILS(&r, 2, "--bogus");
}

static void test_synth_and_denoise(hush_device dev) {
  result r;
  hush(&r, "synth --out '" SEQ "' --size 96x64 --frames 12 --camera orbit --seed 7 --quiet");
  CHECK_MSG(r.status == 0 && r.err[0] == '\0', "synth: %s", r.err);
  CHECK(file_exists(SEQ "/cameras.json"));
  CHECK(file_exists(SEQ "/frame_0000.exr") && file_exists(SEQ "/frame_0011.exr"));

  hush(&r, "denoise --filter accumulate --in '" SEQ "' --out '" OUT "' --png --threads 2");
  CHECK_MSG(r.status == 0, "denoise failed: %s", r.err);
  /* progress (plain lines: stderr is a file here) and the summary */
  CHECK_MSG(strstr(r.err, "frame 12/12") && strstr(r.err, "median") && strstr(r.err, "ms/frame"),
            "stderr: %s", r.err);
  CHECK(file_exists(OUT "/cameras.json"));
  CHECK(file_exists(OUT "/frame_0011.exr") && file_exists(OUT "/frame_0011.png"));
  CHECK(!has_tmp_files(OUT));

  /* the output is a sequence with the input's cameras */
  hush_sequence in_seq, out_seq;
  REQUIRE(hush__sequence_read(dev, SEQ, &in_seq) == HUSH_OK);
  const hush_status st = hush__sequence_read(dev, OUT, &out_seq);
  CHECK(st == HUSH_OK);
  if (st == HUSH_OK) {
    CHECK(out_seq.frame_count == 12 && out_seq.width == 96 && out_seq.height == 64);
    CHECK(out_seq.motion == in_seq.motion);
    CHECK(memcmp(out_seq.cameras, in_seq.cameras, 12 * sizeof *in_seq.cameras) == 0);
    hush__sequence_free(&out_seq);
  }
  hush__sequence_free(&in_seq);

  /* a frame range: only those frames, and cameras.json lists only them */
  hush(&r, "denoise --filter accumulate --in '" SEQ "' --out '" WORK "/out2' --quiet --frames 8:");
  CHECK_MSG(r.status == 0 && r.err[0] == '\0', "--frames 8: %s", r.err);
  CHECK(file_exists(WORK "/out2/frame_0008.exr") && file_exists(WORK "/out2/frame_0011.exr") &&
        !file_exists(WORK "/out2/frame_0007.exr"));
  if (hush__sequence_read(dev, WORK "/out2", &out_seq) == HUSH_OK) {
    CHECK(out_seq.frame_count == 4 && strstr(out_seq.files[0], "frame_0008.exr"));
    hush__sequence_free(&out_seq);
  } else {
    CHECK_MSG(0, "out2 is not a sequence");
  }

  /* less noise: RMSE against "ref" over the last frames */
  double in_sum = 0, in_n = 0, out_sum = 0, out_n = 0;
  for (int i = 8; i < 12; i++) {
    char in_path[512], out_path[512];
    snprintf(in_path, sizeof in_path, SEQ "/frame_%04d.exr", i);
    snprintf(out_path, sizeof out_path, OUT "/frame_%04d.exr", i);
    sq_error(dev, in_path, "color", in_path, "ref", &in_sum, &in_n);
    sq_error(dev, out_path, "color", in_path, "ref", &out_sum, &out_n);
  }
  const double rmse_in = sqrt(in_sum / in_n), rmse_out = sqrt(out_sum / out_n);
  printf("RMSE against ref over frames 8-11: input %.4f, accumulate %.4f (ratio %.2f)\n", rmse_in,
         rmse_out, rmse_out / rmse_in);
  CHECK_MSG(rmse_in > 0.01, "the input is not noisy: %.4f", rmse_in);
  CHECK_MSG(rmse_out <= 0.6 * rmse_in, "RMSE %.4f is not below 0.6 x %.4f", rmse_out, rmse_in);

  /* the same run twice gives the same files */
  hush(&r, "denoise --filter accumulate --in '" SEQ "' --out '" WORK "/out3' --quiet --threads 1");
  CHECK(r.status == 0);
  double same = 0, n = 0;
  sq_error(dev, OUT "/frame_0011.exr", "color", WORK "/out3/frame_0011.exr", "color", &same, &n);
  CHECK_MSG(same == 0.0, "threads 1 and 2 differ: %g", same);
}

static void test_convert(hush_device dev) {
  result r;
  hush(&r, "convert '" SEQ "/frame_0003.exr' '" WORK "/ref.pfm' --layer ref");
  CHECK_MSG(r.status == 0, "exr -> pfm: %s", r.err);
  hush(&r, "convert '" WORK "/ref.pfm' '" WORK "/ref.exr'");
  CHECK_MSG(r.status == 0, "pfm -> exr: %s", r.err);
  if (file_exists(WORK "/ref.exr")) {
    double sum = 0, n = 0;
    sq_error(dev, WORK "/ref.exr", "color", SEQ "/frame_0003.exr", "ref", &sum, &n);
    CHECK_MSG(sum == 0.0, "EXR -> PFM -> EXR changed the pixels: %g", sum);
  }
  hush(&r, "convert '" SEQ "/frame_0003.exr' '" WORK "/f.png' --exposure -1 --tonemap aces");
  CHECK_MSG(r.status == 0 && file_exists(WORK "/f.png"), "exr -> png: %s", r.err);
  hush(&r, "convert '" WORK "/f.png' '" WORK "/f.exr' --layer albedo");
  CHECK_MSG(r.status == 0, "png -> exr: %s", r.err);
  hush(&r, "convert '" SEQ "/frame_0003.exr' '" WORK "/half.exr' --half --layer normal");
  CHECK_MSG(r.status == 0, "exr -> exr: %s", r.err);

  hush(&r, "convert '" SEQ "/frame_0003.exr' '" WORK "/f.tif'");
  CHECK_FAILS(&r, 2, ".tif");
  hush(&r, "convert '" SEQ "/frame_0003.exr' '" WORK "/m.png' --layer nosuch");
  CHECK_FAILS(&r, 1, "nosuch");
  hush(&r, "convert '" WORK "/missing.exr' '" WORK "/m.png'");
  CHECK_FAILS(&r, 1, "missing.exr");
  hush(&r, "convert '" SEQ "/frame_0003.exr' '" WORK "/m.pfm' --tonemap aces");
  CHECK_FAILS(&r, 2, "PNG");
}

/* hush bench: the table and the CSV name every stage; bad input fails. */
static void test_bench(void) {
  result r;
  hush(&r, "bench --filters accumulate --size 48x32 --frames 4 --warmup 1 --distinct 3 "
           "--threads 1 --set alpha_min=0.1 --csv '" WORK "/bench.csv'");
  CHECK_MSG(r.status == 0, "bench: %s", r.err);
  CHECK(strstr(r.out, "accumulate") && strstr(r.out, "total") && strstr(r.out, "median"));
  char csv[8192];
  read_file(WORK "/bench.csv", csv, sizeof csv);
  CHECK(strncmp(csv, "filter,stage,width,height,frames,threads,cpu,median_ms", 54) == 0);
  CHECK(strstr(csv, "accumulate,total,48,32,4,1,") != NULL);
  CHECK(strstr(csv, "accumulate,reproject,") != NULL);
  /* the machine: the CPU's family and model and the build's vectors (the
   * VMs' model names do not tell their generations apart) */
  CHECK_MSG(strstr(r.out, " build)") && strstr(csv, " build)"), "bench's CPU: %.200s", r.out);
  /* the optional outputs bound too (fitted, history_length) */
  hush(&r, "bench --filters bmfr --size 64x48 --frames 2 --warmup 1 --distinct 2 --threads 1 "
           "--all-outputs");
  CHECK_MSG(r.status == 0, "bench --all-outputs: %s", r.err);
  CHECK(strstr(r.out, "bmfr") && strstr(r.out, "total"));
  hush(&r, "bench --filters bmfr --size 64x48 --frames 2 --all-outputs=1");
  CHECK_FAILS(&r, 2, "--all-outputs");
  hush(&r, "bench --filters nosuch --size 48x32");
  CHECK_FAILS(&r, 1, "nosuch");
  hush(&r, "bench --size 0x32");
  CHECK_FAILS(&r, 2, "--size");
  hush(&r, "bench --filters accumulate --size 48x32 --frames 2 --set alpha_min=7");
  CHECK_FAILS(&r, 1, "alpha_min");
}

/* Runs denoise on dir into a fresh output dir and checks the failure. */
static void denoise_fails(result *r, const char *in, const char *extra) {
  char args[2048];
  sh("rm -rf '" WORK "/bad_out'");
  snprintf(args, sizeof args, "denoise --filter accumulate --in '%s' --out '" WORK "/bad_out' --quiet %s",
           in, extra);
  hush(r, args);
  CHECK_MSG(!has_tmp_files(WORK "/bad_out"), "temporary files left by: %s", args);
  CHECK_MSG(!file_exists(WORK "/bad_out/cameras.json"), "cameras.json written by a failed run: %s", args);
}

static void test_bad_inputs(hush_device dev) {
  const char *bad = WORK "/bad";
  result r;
  write_small_sequence(dev, bad);

  /* parameters */
  denoise_fails(&r, bad, "--set nosuch_param=1");
  CHECK_FAILS(&r, 1, "nosuch_param");
  denoise_fails(&r, bad, "--set alpha_min=3");
  CHECK_FAILS(&r, 1, "alpha_min", "outside");
  denoise_fails(&r, bad, "--set alpha_min=abc");
  CHECK_FAILS(&r, 1, "alpha_min", "abc");
  denoise_fails(&r, bad, "--set use_id=maybe");
  CHECK_FAILS(&r, 1, "use_id", "maybe");
  denoise_fails(&r, bad, "--set alpha_min");
  CHECK_FAILS(&r, 2, "KEY=VALUE");
  sh("rm -rf '" WORK "/bad_out'");
  hush(&r, "denoise --filter nosuch --in '" WORK "/bad' --out '" WORK "/bad_out' --quiet");
  CHECK_FAILS(&r, 1, "nosuch", "accumulate");

  /* usage */
  denoise_fails(&r, bad, "--frobnicate");
  CHECK_FAILS(&r, 2, "--frobnicate");
  denoise_fails(&r, bad, "--frames 9:");
  CHECK_FAILS(&r, 1, "--frames", "4 frames");
  denoise_fails(&r, bad, "--frames x");
  CHECK_FAILS(&r, 2, "--frames");
  hush(&r, "denoise --in '" WORK "/bad' --out '" WORK "/bad_out'");
  CHECK_FAILS(&r, 2, "--filter");

  /* the input directory and cameras.json */
  denoise_fails(&r, WORK "/does_not_exist", "");
  CHECK_FAILS(&r, 1, "does_not_exist");
  sh("rm -f '" WORK "/bad/cameras.json'");
  denoise_fails(&r, bad, "");
  CHECK_FAILS(&r, 1, "cameras.json");
  sh("printf '{ \"format\": \"hush-cameras/1\", \"frames\": [' > '" WORK "/bad/cameras.json'");
  denoise_fails(&r, bad, "");
  CHECK_FAILS(&r, 1, "cameras.json");

  /* frames: truncated, missing a required layer, of another size */
  write_small_sequence(dev, bad);
  sh("head -c 300 '" WORK "/bad/frame_0002.exr' > '" WORK "/t.exr' && mv '" WORK
     "/t.exr' '" WORK "/bad/frame_0002.exr'");
  denoise_fails(&r, bad, "");
  CHECK_FAILS(&r, 1, "frame_0002.exr");

  write_small_sequence(dev, bad);
  drop_layer(dev, WORK "/bad/frame_0002.exr", "normal");
  denoise_fails(&r, bad, "");
  CHECK_FAILS(&r, 1, "frame_0002.exr", "'normal'", "N.X", "accumulate");

  write_small_sequence(dev, bad);
  {
    hush_synth_params p;
    hush__synth_defaults(&p);
    p.width = 40;
    p.height = 30;
    hush_frame f = NULL;
    REQUIRE(hush__synth_frame(dev, &p, 1, &f, NULL) == HUSH_OK);
    REQUIRE(hush_frame_write_exr(f, WORK "/bad/frame_0001.exr", HUSH_EXR_HALF) == HUSH_OK);
    hush_frame_release(f);
  }
  denoise_fails(&r, bad, "");
  CHECK_FAILS(&r, 1, "frame_0001.exr", "40x30");

  /* without --quiet the error is still the last line */
  sh("rm -rf '" WORK "/bad_out'");
  hush(&r, "denoise --filter accumulate --in '" WORK "/bad' --out '" WORK "/bad_out'");
  CHECK(r.status == 1 && strstr(r.err, "frame 1/4") && strstr(r.err, "hush denoise: ") &&
        strstr(strstr(r.err, "hush denoise: "), "frame_0001.exr"));

  /* the output directory must not be the input */
  write_small_sequence(dev, bad);
  hush(&r, "denoise --filter accumulate --in '" WORK "/bad' --out '" WORK "/bad/' --quiet");
  CHECK_FAILS(&r, 1, "input directory");

  /* synth */
  hush(&r, "synth --out '" WORK "/s' --size 0x10");
  CHECK_FAILS(&r, 2, "--size");
  hush(&r, "synth --out '" WORK "/s' --camera sideways");
  CHECK_FAILS(&r, 2, "sideways");
  hush(&r, "synth --size 8x8");
  CHECK_FAILS(&r, 2, "--out");
}

int main(void) {
  sh("rm -rf '" WORK "' && mkdir -p '" WORK "'");
  hush_device dev = hush_device_new("threads=2");
  REQUIRE(dev);
  test_top_level();
  test_filters();
  test_synth_and_denoise(dev);
  test_convert(dev);
  test_bad_inputs(dev);
  test_bench();
  hush_device_release(dev);
  return check_summary();
}

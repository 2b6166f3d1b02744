/*
 * main.c — the `hush` command: dispatches `hush <subcommand> ...` to the
 * cmd_*.c files through one table, and answers --help and --version.
 * A new subcommand is one cmd_<name>.c and one row in `commands`.
 */
#include "cli.h"

#include <stdio.h>
#include <string.h>

int cmd_filters(int argc, char **argv);
int cmd_denoise(int argc, char **argv);
int cmd_convert(int argc, char **argv);
int cmd_synth(int argc, char **argv);
int cmd_bench(int argc, char **argv);
int cmd_render(int argc, char **argv);
int cmd_eval(int argc, char **argv);
int cmd_compare(int argc, char **argv);
int cmd_train_nca(int argc, char **argv);

static const struct {
  const char *name;
  cli_command_fn run;
  const char *summary;
} commands[] = {
    {"filters", cmd_filters, "list the filters with their parameters and images"},
    {"denoise", cmd_denoise, "run a filter over a frame sequence"},
    {"convert", cmd_convert, "convert between EXR, PNG and PFM"},
    {"synth", cmd_synth, "write a synthetic noisy sequence with its reference"},
    {"bench", cmd_bench, "time filters on frames in memory (synthetic or rendered)"},
    {"render", cmd_render, "path-trace a noisy frame sequence (or references) of a scene"},
    {"eval", cmd_eval, "compare filters against references: metrics, timings, report"},
    {"compare", cmd_compare, "mean luminance ratio and RMSE of a render against a reference"},
    {"train-nca", cmd_train_nca, "train the weights of the nca filter on rendered frames"},
};

#define COMMAND_COUNT (sizeof commands / sizeof commands[0])

static void print_help(FILE *out) {
  fprintf(out,
          "usage: hush <command> [options]\n"
          "       hush --help | --version\n"
          "\n"
          "Real-time denoising filters for path-traced frame sequences.\n"
          "\n"
          "commands:\n");
  for (size_t i = 0; i < COMMAND_COUNT; i++)
    fprintf(out, "  %-10s %s\n", commands[i].name, commands[i].summary);
  fprintf(out,
          "\n"
          "`hush <command> --help` describes a command's options.\n"
          "Exit status: 0 success, 1 runtime error, 2 usage error.\n");
}

int main(int argc, char **argv) {
  if (argc < 2) {
    print_help(stderr);
    return CLI_EXIT_USAGE;
  }
  const char *name = argv[1];
  if (strcmp(name, "help") == 0 && argc >= 3) {
    /* `hush help denoise` is `hush denoise --help` */
    char help[] = "--help";
    char *sub[] = {argv[2], help, NULL};
    for (size_t i = 0; i < COMMAND_COUNT; i++)
      if (strcmp(commands[i].name, argv[2]) == 0) return commands[i].run(2, sub);
    name = argv[2];
  } else if (cli_is_help(name) || strcmp(name, "help") == 0) {
    print_help(stdout);
    return 0;
  }
  if (strcmp(name, "--version") == 0 || strcmp(name, "-V") == 0) {
    printf("hush %s\n", hush_version());
    return 0;
  }
  for (size_t i = 0; i < COMMAND_COUNT; i++)
    if (strcmp(commands[i].name, name) == 0) return commands[i].run(argc - 1, argv + 1);

  char names[256] = "";
  for (size_t i = 0; i < COMMAND_COUNT; i++) {
    const size_t len = strlen(names);
    snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "", commands[i].name);
  }
  fprintf(stderr, "hush: unknown command '%s' (commands: %s; see hush --help)\n", name, names);
  return CLI_EXIT_USAGE;
}

/*
 * cli.h — what every `hush` subcommand shares: option parsing (--flag value
 * and --flag=value), value parsers (sizes, frame ranges, numbers, tone
 * mapping), the device made from --threads, and error reporting as one line
 * "hush <cmd>: <message>" on stderr.
 *
 * Exit codes: 0 success, 1 runtime error (bad file, filter failure),
 * 2 usage error (unknown option, malformed value).
 */
#ifndef HUSH_TOOLS_CLI_H
#define HUSH_TOOLS_CLI_H

#include "hush.h"

#include <stdint.h>
#include <stdio.h>

#define CLI_EXIT_RUNTIME 1
#define CLI_EXIT_USAGE 2

#if defined(__GNUC__)
#  define CLI_PRINTF(a, b) __attribute__((format(printf, a, b)))
#  define CLI_NORETURN __attribute__((noreturn))
#else
#  define CLI_PRINTF(a, b)
#  define CLI_NORETURN
#endif

/* A subcommand: argv[0] is the subcommand name, options follow. */
typedef int (*cli_command_fn)(int argc, char **argv);

/* The walk over a subcommand's arguments. */
typedef struct cli_args {
  const char *cmd; /* "denoise", for messages */
  int argc;
  char **argv;
  int next;        /* index of the next argument to look at */
  int only_positional; /* after "--" */
} cli_args;

void cli_args_init(cli_args *a, const char *cmd, int argc, char **argv);

/* Takes the next argument into *arg; 0 when there are none left. */
int cli_next(cli_args *a, const char **arg);

/*
 * Whether arg is the option `flag` (e.g. "--out") that takes a value:
 * "--out DIR" (the value is taken from the next argument) or "--out=DIR".
 * A missing value is a usage error (exits 2).
 */
int cli_option(cli_args *a, const char *arg, const char *flag, const char **value);

/* Whether arg is the switch `flag` (no value); "--half=1" is a usage error. */
int cli_switch(cli_args *a, const char *arg, const char *flag);

/* Whether arg asks for help (-h, --help). */
int cli_is_help(const char *arg);

/* Whether arg is positional: not an option, or anything after "--". */
int cli_is_positional(const cli_args *a, const char *arg);

/* "unknown option '--x' (see hush <cmd> --help)", exits 2. */
CLI_NORETURN void cli_unknown_option(const cli_args *a, const char *arg);

/* Prints "hush <cmd>: <message>" and exits 2. */
CLI_NORETURN void cli_usage_error(const char *cmd, const char *fmt, ...) CLI_PRINTF(2, 3);

/* Prints "hush <cmd>: <message>" and returns CLI_EXIT_RUNTIME. */
int cli_error(const char *cmd, const char *fmt, ...) CLI_PRINTF(2, 3);

/*
 * Prints the device's first unread error as "hush <cmd>: <context>: <message>"
 * (context may be NULL, and is left out when the message already contains
 * it, as a file name often is), drains the rest, and returns
 * CLI_EXIT_RUNTIME.
 * With no error recorded it prints context and the status name.
 */
int cli_device_error(const char *cmd, hush_device device, hush_status status,
                     const char *context);

/* Value parsers: on a malformed or out-of-range value they report
 * "--flag: ..." as a usage error and exit 2. */
uint32_t cli_parse_uint(const char *cmd, const char *flag, const char *text, uint32_t min,
                        uint32_t max);
float cli_parse_float(const char *cmd, const char *flag, const char *text, float min, float max);
/* "WxH", both in [1, 16384]. */
void cli_parse_size(const char *cmd, const char *flag, const char *text, uint32_t *width,
                    uint32_t *height);
/* "A:B" (frames A .. B-1, either side may be empty), or "A" (just frame A).
 * *last is UINT32_MAX when B is empty: "to the end". */
void cli_parse_range(const char *cmd, const char *flag, const char *text, uint32_t *first,
                     uint32_t *last);
/* clamp | reinhard | aces */
hush_tonemap cli_parse_tonemap(const char *cmd, const char *flag, const char *text);

/* A device with "threads=N" (0: one per core); NULL after printing why. */
hush_device cli_device_new(const char *cmd, uint32_t threads);

/* Whether path names an existing directory. */
int cli_is_dir(const char *path);
/* path's extension, lower-cased, without the dot, into buf ("" if none). */
void cli_extension(const char *path, char *buf, size_t size);
/* The last component of a path ("frame_0002.exr"). */
const char *cli_basename(const char *path);

/* The EXR channel names of a layer, for messages: "normal.X, normal.Y, normal.Z". */
void cli_layer_channels(const char *layer, int channels, char *buf, size_t size);

/*
 * Binds every input image of the filter's class to the frame's layer of the
 * same name, and unbinds optional ones the frame lacks; a missing required
 * layer or one with too few channels is an error naming `file`. Returns 0 or
 * CLI_EXIT_RUNTIME (message printed).
 */
int cli_bind_inputs(const char *cmd, hush_device device, hush_filter filter, hush_frame frame,
                    const char *file);

/*
 * A --set KEY=VALUE on a filter: hush_filter_set_string, except the key
 * "weights" of the nca filter, which loads a weights file written by `hush
 * train-nca` (hush_nca_load_weights; the value "builtin" restores the
 * built-in weights). The parameter tables hold numbers only, so the file is
 * not one of them.
 */
hush_status cli_filter_set(hush_filter filter, const char *key, const char *value);
/* Whether cli_filter_set takes key for this filter. */
int cli_filter_has_param(hush_filter filter, const char *key);

/* Writes s to f as a JSON string literal (quoted, escaped). */
void cli_json_string(FILE *f, const char *s);

#endif

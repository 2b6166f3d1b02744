/*
 * cmd_filters.c — `hush filters [NAME] [--markdown]`: describes the filter
 * classes from the library's static tables (doc, paper, parameters, images),
 * as aligned text or as Markdown tables for the documentation.
 */
#include "cli.h"

#include <stdio.h>
#include <string.h>

static const char *const help_text =
    "usage: hush filters [NAME] [--markdown | --names]\n"
    "\n"
    "Lists every filter this build provides, or only NAME, with its one-line\n"
    "description, the paper it follows, its parameters (name, type, default,\n"
    "range or values, description) and its images (name, input or output,\n"
    "required or optional, channels, description). Parameters are set with\n"
    "`hush denoise --set name=value`; images are bound to frame layers of the\n"
    "same name.\n"
    "\n"
    "options:\n"
    "  --markdown   print Markdown tables (for docs/) instead of text\n"
    "  --names      print only the filter names, one per line (for scripts)\n"
    "  -h, --help   show this help\n";

static const char *type_name(hush_param_type t) {
  switch (t) {
  case HUSH_PARAM_BOOL: return "bool";
  case HUSH_PARAM_INT: return "int";
  case HUSH_PARAM_FLOAT: return "float";
  case HUSH_PARAM_ENUM: return "enum";
  }
  return "?";
}

/* The default as a user would type it for --set. */
static void format_default(const hush_param_info *p, char *buf, size_t size) {
  const int i = (int)p->default_value;
  switch (p->type) {
  case HUSH_PARAM_BOOL: snprintf(buf, size, "%s", p->default_value != 0.0 ? "true" : "false"); return;
  case HUSH_PARAM_INT: snprintf(buf, size, "%d", i); return;
  case HUSH_PARAM_FLOAT: snprintf(buf, size, "%g", p->default_value); return;
  case HUSH_PARAM_ENUM:
    snprintf(buf, size, "%s", p->enum_names && i >= 0 && i <= (int)p->max_value ? p->enum_names[i] : "?");
    return;
  }
  snprintf(buf, size, "?");
}

/* The accepted values: "[0, 1]", "true | false", "error | replace". */
static void format_range(const hush_param_info *p, const char *sep, char *buf, size_t size) {
  switch (p->type) {
  case HUSH_PARAM_BOOL: snprintf(buf, size, "true%sfalse", sep); return;
  case HUSH_PARAM_INT:
  case HUSH_PARAM_FLOAT: snprintf(buf, size, "[%g, %g]", p->min_value, p->max_value); return;
  case HUSH_PARAM_ENUM:
    buf[0] = '\0';
    for (int k = 0; p->enum_names && k <= (int)p->max_value; k++) {
      const size_t len = strlen(buf);
      snprintf(buf + len, size - len, "%s%s", k ? sep : "", p->enum_names[k]);
    }
    return;
  }
  snprintf(buf, size, "?");
}

static void print_text(const hush_filter_class_info *c) {
  printf("%s - %s\n", c->name, c->doc ? c->doc : "");
  if (c->paper && *c->paper) printf("  follows: %s\n", c->paper);

  int wn = 4, wd = 7, wr = 5;
  for (uint32_t i = 0; i < c->param_count; i++) {
    char def[64], range[256];
    format_default(&c->params[i], def, sizeof def);
    format_range(&c->params[i], " | ", range, sizeof range);
    const int n = (int)strlen(c->params[i].name), d = (int)strlen(def), r = (int)strlen(range);
    wn = n > wn ? n : wn;
    wd = d > wd ? d : wd;
    wr = r > wr ? r : wr;
  }
  printf("  parameters:\n");
  printf("    %-*s  %-5s  %-*s  %-*s  %s\n", wn, "name", "type", wd, "default", wr, "range",
         "description");
  for (uint32_t i = 0; i < c->param_count; i++) {
    const hush_param_info *p = &c->params[i];
    char def[64], range[256];
    format_default(p, def, sizeof def);
    format_range(p, " | ", range, sizeof range);
    printf("    %-*s  %-5s  %-*s  %-*s  %s\n", wn, p->name, type_name(p->type), wd, def, wr, range,
           p->doc ? p->doc : "");
  }
  if (strcmp(c->name, "nca") == 0)
    printf("  weights: --set weights=FILE loads a weights file from `hush train-nca` (builtin: the\n"
           "  built-in ones); the API's hush_nca_load_weights (docs/nca.md)\n");

  int wi = 4;
  for (uint32_t i = 0; i < c->image_count; i++) {
    const int n = (int)strlen(c->images[i].name);
    wi = n > wi ? n : wi;
  }
  printf("  images:\n");
  printf("    %-*s  %-6s  %-8s  %-8s  %s\n", wi, "name", "role", "required", "channels",
         "description");
  for (uint32_t i = 0; i < c->image_count; i++) {
    const hush_image_info *im = &c->images[i];
    printf("    %-*s  %-6s  %-8s  %-8d  %s\n", wi, im->name,
           im->role == HUSH_IMAGE_INPUT ? "input" : "output", im->required ? "yes" : "no",
           im->channels, im->doc ? im->doc : "");
  }
}

/* Markdown table cells must not contain a bare '|'. */
static void md_cell(const char *text) {
  for (const char *c = text ? text : ""; *c; c++) {
    if (*c == '|') putchar('\\');
    putchar(*c);
  }
}

static void print_markdown(const hush_filter_class_info *c) {
  printf("## `%s`\n\n", c->name);
  printf("%s\n\n", c->doc ? c->doc : "");
  if (c->paper && *c->paper) printf("Follows: %s\n\n", c->paper);

  printf("| Parameter | Type | Default | Range | Description |\n");
  printf("|---|---|---|---|---|\n");
  for (uint32_t i = 0; i < c->param_count; i++) {
    const hush_param_info *p = &c->params[i];
    char def[64], range[256];
    format_default(p, def, sizeof def);
    printf("| `%s` | %s | `%s` | ", p->name, type_name(p->type), def);
    if (p->type == HUSH_PARAM_BOOL || p->type == HUSH_PARAM_ENUM) {
      format_range(p, "`, `", range, sizeof range);
      printf("`");
      md_cell(range);
      printf("`");
    } else {
      format_range(p, ", ", range, sizeof range);
      md_cell(range);
    }
    printf(" | ");
    md_cell(p->doc);
    printf(" |\n");
  }
  if (strcmp(c->name, "nca") == 0)
    printf("\nWeights: `--set weights=FILE` on the command line loads a weights file from `hush "
           "train-nca` (`builtin`: the built-in ones); the API's `hush_nca_load_weights` "
           "(docs/nca.md).\n");
  printf("\n| Image | Role | Required | Channels | Description |\n");
  printf("|---|---|---|---|---|\n");
  for (uint32_t i = 0; i < c->image_count; i++) {
    const hush_image_info *im = &c->images[i];
    printf("| `%s` | %s | %s | %d | ", im->name, im->role == HUSH_IMAGE_INPUT ? "input" : "output",
           im->required ? "yes" : "no", im->channels);
    md_cell(im->doc);
    printf(" |\n");
  }
}

static void print_class(const hush_filter_class_info *c, int markdown) {
  if (markdown)
    print_markdown(c);
  else
    print_text(c);
}

int cmd_filters(int argc, char **argv) {
  cli_args a;
  cli_args_init(&a, "filters", argc, argv);
  const char *arg, *name = NULL;
  int markdown = 0, names_only = 0;
  while (cli_next(&a, &arg)) {
    if (cli_is_help(arg)) {
      fputs(help_text, stdout);
      return 0;
    } else if (cli_switch(&a, arg, "--markdown")) {
      markdown = 1;
    } else if (cli_switch(&a, arg, "--names")) {
      names_only = 1;
    } else if (cli_is_positional(&a, arg) && !name) {
      name = arg;
    } else if (cli_is_positional(&a, arg)) {
      cli_usage_error(a.cmd, "unexpected argument '%s' (one filter name at most)", arg);
    } else {
      cli_unknown_option(&a, arg);
    }
  }

  if (name) {
    const hush_filter_class_info *c = hush_filter_class_find(name);
    if (!c) {
      char known[512] = "";
      for (uint32_t i = 0; i < hush_filter_class_count(); i++) {
        const size_t len = strlen(known);
        snprintf(known + len, sizeof known - len, "%s%s", i ? ", " : "",
                 hush_filter_class_at(i)->name);
      }
      return cli_error(a.cmd, "unknown filter '%s' (known: %s)", name, known);
    }
    print_class(c, markdown);
    return 0;
  }
  const uint32_t n = hush_filter_class_count();
  for (uint32_t i = 0; i < n && names_only; i++) printf("%s\n", hush_filter_class_at(i)->name);
  for (uint32_t i = 0; i < n && !names_only; i++) {
    if (i) printf("\n");
    print_class(hush_filter_class_at(i), markdown);
  }
  return 0;
}

/*
 * atomic_file.h — write-to-temp-then-rename, so an output file is either the
 * old one or the complete new one, never half written; and mkdir -p for
 * output directories.
 */
#ifndef HUSH_IO_ATOMIC_FILE_H
#define HUSH_IO_ATOMIC_FILE_H

#include "hush.h"

#include <stdio.h>

#define HUSH_PATH_MAX 4096

/* Picks a unique temporary name in path's directory (path + ".tmp-XXXXXX")
 * and creates it; tmp receives the name. Returns NULL (reported) on failure. */
FILE *hush__atomic_open(hush_device device, const char *path, char tmp[HUSH_PATH_MAX]);
/* Like hush__atomic_open but only reserves the name (for libraries that
 * open files themselves, such as OpenEXR); the empty file exists. */
hush_status hush__atomic_reserve(hush_device device, const char *path, char tmp[HUSH_PATH_MAX]);
/* Flushes and closes f (if not NULL) and renames tmp to path; on any failure
 * removes tmp and reports. */
hush_status hush__atomic_commit(hush_device device, FILE *f, const char *tmp, const char *path);
/* Closes f (if not NULL) and removes tmp. */
void hush__atomic_abort(FILE *f, const char *tmp);

/* Makes dir and its missing parents (mkdir -p); reports on device. */
hush_status hush__make_dirs(hush_device device, const char *dir);

#endif

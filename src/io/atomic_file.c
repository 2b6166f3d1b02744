/*
 * atomic_file.c — output files are written to a temporary file in the
 * target's directory and renamed over the target only once complete, so a
 * reader sees either the old file or the whole new one, and a failed write
 * leaves nothing behind.
 */
#include "io/atomic_file.h"

#include "core/device.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* mkstemp() creates files readable by their owner only; an output picture
 * should get the permissions of the file it replaces, or the usual 0644. */
static void give_output_mode(int fd, const char *path) {
  struct stat st;
  mode_t mode = 0644;
  if (stat(path, &st) == 0) mode = st.st_mode & 07777;
  (void)fchmod(fd, mode); /* best effort: the file is still correct without it */
}

/* Creates path.tmp-XXXXXX and returns its descriptor in *fd. */
static hush_status make_temp(hush_device device, const char *path, char tmp[HUSH_PATH_MAX],
                             int *fd) {
  tmp[0] = '\0';
  if (!path || !*path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "output path is NULL or empty");
  const int n = snprintf(tmp, HUSH_PATH_MAX, "%s.tmp-XXXXXX", path);
  if (n < 0 || n >= HUSH_PATH_MAX) {
    tmp[0] = '\0';
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "output path is too long: '%.200s...'",
                      path);
  }
  *fd = mkstemp(tmp);
  if (*fd < 0) {
    const int err = errno;
    tmp[0] = '\0';
    return hush__fail(device, HUSH_ERROR_IO, "cannot create a temporary file for '%s': %s", path,
                      strerror(err));
  }
  give_output_mode(*fd, path);
  return HUSH_OK;
}

FILE *hush__atomic_open(hush_device device, const char *path, char tmp[HUSH_PATH_MAX]) {
  int fd = -1;
  if (make_temp(device, path, tmp, &fd) != HUSH_OK) return NULL;
  FILE *f = fdopen(fd, "wb");
  if (!f) {
    const int err = errno;
    close(fd);
    unlink(tmp);
    tmp[0] = '\0';
    hush__fail(device, HUSH_ERROR_IO, "cannot open a temporary file for '%s': %s", path,
               strerror(err));
  }
  return f;
}

hush_status hush__atomic_reserve(hush_device device, const char *path, char tmp[HUSH_PATH_MAX]) {
  int fd = -1;
  const hush_status status = make_temp(device, path, tmp, &fd);
  if (status == HUSH_OK) close(fd);
  return status;
}

hush_status hush__atomic_commit(hush_device device, FILE *f, const char *tmp, const char *path) {
  if (f) {
    /* Write errors (a full disk) often show only when buffers are flushed. */
    int err = 0;
    errno = 0;
    if (fflush(f) != 0 || ferror(f)) err = errno ? errno : EIO;
    if (fclose(f) != 0 && !err) err = errno;
    if (err) {
      unlink(tmp);
      return hush__fail(device, HUSH_ERROR_IO, "cannot write '%s': %s", path, strerror(err));
    }
  }
  if (rename(tmp, path) != 0) {
    const int err = errno;
    unlink(tmp);
    return hush__fail(device, HUSH_ERROR_IO, "cannot replace '%s': %s", path, strerror(err));
  }
  return HUSH_OK;
}

void hush__atomic_abort(FILE *f, const char *tmp) {
  if (f) fclose(f);
  if (tmp && *tmp) unlink(tmp);
}

hush_status hush__make_dirs(hush_device device, const char *dir) {
  char path[HUSH_PATH_MAX];
  if (!dir || !*dir) return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "directory name is empty");
  if (strlen(dir) >= sizeof path)
    return hush__fail(device, HUSH_ERROR_INVALID_ARGUMENT, "directory name is too long: %.64s...", dir);
  strcpy(path, dir);
  /* Make each prefix that ends at a '/', then the whole path. */
  for (char *c = path + 1;; c++) {
    const int end = *c == '\0';
    if (*c != '/' && !end) continue;
    *c = '\0';
    if (mkdir(path, 0777) != 0 && errno != EEXIST)
      return hush__fail(device, HUSH_ERROR_IO, "cannot create directory '%s': %s", path,
                        strerror(errno));
    if (end) break;
    *c = '/';
  }
  struct stat sb;
  if (stat(dir, &sb) != 0 || !S_ISDIR(sb.st_mode))
    return hush__fail(device, HUSH_ERROR_IO, "'%s' exists and is not a directory", dir);
  return HUSH_OK;
}

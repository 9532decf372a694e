/* Input and output files: the regular-file checks every reader and writer shares, and the
 * atomic write (a temporary file next to the output, renamed into place). */
#define _GNU_SOURCE
#include "core/internal.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

static const char *const NOT_REGULAR = "is not a regular file (a FIFO, device or socket)";

FILE *kpcn_fopen_input(const char *path, const char **why) {
  static const char *const no_path = "no file name";
  if (!path || !*path) {
    errno = ENOENT;
    if (why) *why = no_path;
    return NULL;
  }
  /* O_NONBLOCK so a FIFO with no writer is refused here instead of blocking the open (which a
   * signal handler with SA_RESTART could not interrupt); cleared again for regular files. */
  int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    if (why) *why = strerror(errno);
    return NULL;
  }
  struct stat st;
  const char *bad = NULL;
  int e = 0;
  if (fstat(fd, &st) != 0) {
    e = errno;
    bad = strerror(e);
  } else if (S_ISDIR(st.st_mode)) {
    e = EISDIR;
    bad = "is a directory";
  } else if (!S_ISREG(st.st_mode)) {
    e = EINVAL;
    bad = NOT_REGULAR;
  }
  FILE *f = NULL;
  if (!bad) {
    int fl = fcntl(fd, F_GETFL);
    if (fl >= 0) (void)fcntl(fd, F_SETFL, fl & ~O_NONBLOCK);
    f = fdopen(fd, "rb");
    if (!f) {
      e = errno;
      bad = strerror(e);
    }
  }
  if (!f) {
    close(fd);
    if (why) *why = bad;
    errno = e;
  }
  return f;
}

/* The file a write to `path` replaces: path itself, or a symbolic link's final target (a
 * link is followed, not replaced). Fails for a dangling link or one whose target is not a
 * regular file. */
static kpcn_status output_target(const char *path, const char *what, char *out, size_t outsz) {
  struct stat st;
  if (!path || !*path)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: empty file name", what ? what : "output");
  snprintf(out, outsz, "%s", path);
  if (lstat(path, &st) != 0) return KPCN_OK; /* a new file; its folder is checked apart */
  if (S_ISLNK(st.st_mode)) {
    char *real = realpath(path, NULL);
    if (!real)
      return kpcn_fail(KPCN_ERR_IO, "%s '%s' is a symbolic link to a missing file", what, path);
    int n = snprintf(out, outsz, "%s", real);
    free(real);
    if (n < 0 || (size_t)n >= outsz)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s '%.64s...': path too long", what, path);
    if (stat(out, &st) != 0)
      return kpcn_fail(KPCN_ERR_IO, "%s '%s': %s", what, path, strerror(errno));
  }
  if (S_ISDIR(st.st_mode))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s '%s' is a directory", what, path);
  if (!S_ISREG(st.st_mode))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s '%s' %s: it would be replaced by a new file, not written into", what, path,
                     NOT_REGULAR);
  return KPCN_OK;
}

kpcn_status kpcn_check_output_path(const char *path, const char *what) {
  char target[PATH_MAX];
  if (!what) what = "output";
  KPCN_TRY(output_target(path, what, target, sizeof target));
  char dir[PATH_MAX];
  snprintf(dir, sizeof dir, "%s", target);
  char *slash = strrchr(dir, '/');
  if (!slash)
    snprintf(dir, sizeof dir, ".");
  else if (slash == dir)
    dir[1] = 0; /* "/x" */
  else
    *slash = 0;
  struct stat st;
  if (stat(dir, &st) != 0)
    return kpcn_fail(KPCN_ERR_IO, "%s '%s': folder '%s': %s", what, path, dir, strerror(errno));
  if (!S_ISDIR(st.st_mode))
    return kpcn_fail(KPCN_ERR_IO, "%s '%s': '%s' is not a folder", what, path, dir);
  if (access(dir, W_OK | X_OK) != 0)
    return kpcn_fail(KPCN_ERR_IO, "%s '%s': cannot write in folder '%s': %s", what, path, dir,
                     strerror(errno));
  return KPCN_OK;
}

int kpcn_has_extension(const char *path, const char *ext) {
  const size_t n = path ? strlen(path) : 0, k = strlen(ext);
  return n >= k && strcasecmp(path + n - k, ext) == 0;
}

kpcn_status kpcn_check_extension(const char *path, const char *ext, const char *what,
                                 const char *format) {
  if (kpcn_has_extension(path, ext)) return KPCN_OK;
  return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s '%s' must end in %s (it is written as %s)", what,
                   path ? path : "", ext, format);
}

/* path with its folder made canonical (realpath), for a file that may not exist yet; the text
 * itself when the folder does not exist either. */
static void canonical_path(const char *path, char *out, size_t n) {
  const char *slash = strrchr(path, '/');
  char dir[PATH_MAX], real[PATH_MAX];
  if (!slash)
    snprintf(dir, sizeof dir, ".");
  else
    snprintf(dir, sizeof dir, "%.*s", slash == path ? 1 : (int)(slash - path), path);
  if (realpath(dir, real))
    snprintf(out, n, "%s/%s", real, slash ? slash + 1 : path);
  else
    snprintf(out, n, "%s", path);
}

int kpcn_same_file(const char *a, const char *b) {
  struct stat sa, sb;
  if (!a || !b) return 0;
  if (stat(a, &sa) == 0 && stat(b, &sb) == 0)
    return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
  char ca[PATH_MAX + 256], cb[PATH_MAX + 256];
  canonical_path(a, ca, sizeof ca);
  canonical_path(b, cb, sizeof cb);
  return strcmp(ca, cb) == 0;
}

kpcn_status kpcn_check_not_input(const char *output, const char *out_what, const char *input,
                                 const char *in_what) {
  if (kpcn_same_file(output, input))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s '%s' is the same file as %s '%s': writing it would destroy the input",
                     out_what, output, in_what, input);
  return KPCN_OK;
}

/* Unique per process AND per call: two threads (or two writers of one process) writing the
 * same path must not share a temp file, or one truncates the other's half-written data. The
 * name keeps the output's ("x.exr.tmp.PID.K") unless that would pass the file-name limit;
 * then it is a short hidden one in the same folder (".kpcn.tmp.PID.K"). */
kpcn_status kpcn_temp_path(char *out, size_t outsz, const char *path) {
  static atomic_ulong counter;
  char target[PATH_MAX];
  KPCN_TRY(output_target(path, "output", target, sizeof target));
  const unsigned long k = atomic_fetch_add(&counter, 1);
  char suffix[64];
  snprintf(suffix, sizeof suffix, ".tmp.%ld.%lu", (long)getpid(), k);
  const char *slash = strrchr(target, '/');
  const size_t base = strlen(slash ? slash + 1 : target);
  int n;
  if (base + strlen(suffix) <= NAME_MAX)
    n = snprintf(out, outsz, "%s%s", target, suffix);
  else
    n = snprintf(out, outsz, "%.*s.kpcn%s", slash ? (int)(slash - target + 1) : 0, target, suffix);
  if (n < 0 || (size_t)n >= outsz)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "path too long for a temporary name: '%.64s...'",
                     path);
  return KPCN_OK;
}

kpcn_status kpcn_commit_file(const char *tmp, const char *path) {
  char target[PATH_MAX];
  kpcn_status st = output_target(path, "output", target, sizeof target);
  if (st != KPCN_OK) {
    unlink(tmp);
    return st;
  }
  if (rename(tmp, target) != 0) {
    int e = errno;
    unlink(tmp);
    return kpcn_fail(KPCN_ERR_IO, "cannot rename '%s' to '%s': %s", tmp, target, strerror(e));
  }
  return KPCN_OK;
}

void kpcn_abort_file(const char *tmp) { unlink(tmp); }

const char *kpcn_write_reason(int err) { return err ? strerror(err) : "short write"; }

int kpcn_path_join(char *out, size_t n, const char *dir, const char *file) {
  const int w = file[0] == '/' || !dir || !dir[0] ? snprintf(out, n, "%s", file)
                                                  : snprintf(out, n, "%s/%s", dir, file);
  return w >= 0 && (size_t)w < n;
}

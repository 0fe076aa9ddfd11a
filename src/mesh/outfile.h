/* outfile.h — output files written safely: the data goes to a temporary file beside the
 * target (same folder, so the rename is atomic) that replaces the target only when every
 * byte was written, so an interrupted or failed write never leaves a truncated file where
 * a good one was (the rename protects against a killed process or a full disk; there is no
 * fsync, so it does not protect against a power cut). Every error names the path and
 * errno's reason. libc only. */
#ifndef LUGAL_OUTFILE_H
#define LUGAL_OUTFILE_H

#include <stdio.h>

typedef struct {
  FILE *f;
  char *path;  /* the target */
  char *tmp;   /* the temporary file */
} outfile;

/* open a temporary file for path (mode 0666 less the umask, like fopen); nonzero with a
 * message in err (errlen bytes) when it cannot */
int outfile_open(outfile *o, const char *path, char *err, size_t errlen);
/* flush, close and rename over the target; on any error the temporary file is removed,
 * the target is left as it was and err says why */
int outfile_commit(outfile *o, char *err, size_t errlen);
/* give up: remove the temporary file, leave the target as it was */
void outfile_abort(outfile *o);

#endif

/* outfile.h — output files written safely: the data goes to a temporary file beside the
 * target (same folder, so the rename is atomic; a short name, so that any legal target name
 * has room) that replaces the target only when every byte was written, so an interrupted or
 * failed write never leaves a truncated file where a good one was (the rename protects
 * against a killed process or a full disk; there is no fsync, so it does not protect
 * against a power cut). A target that is a symbolic link is written through (the file it
 * names is replaced, the link stays), and an existing target's permissions carry over to
 * the new file. Several files that belong together (a .pvtu and its pieces) are each
 * finished under their temporary names and published only when all were written
 * (outfile_finish, then outfile_publish or outfile_abort). The temporary files that exist
 * are tracked, so that a run ended by SIGINT, SIGTERM or SIGHUP removes them
 * (outfile_on_signals). Every error names the path and errno's reason. libc only. */
#ifndef LUGAL_OUTFILE_H
#define LUGAL_OUTFILE_H

#include <stdio.h>
#include <sys/types.h>

typedef struct {
  FILE *f;     /* open while writing; NULL once finished */
  char *path;  /* the file replaced: the target, or the file its links name */
  char *tmp;   /* the temporary file */
  int slot;    /* its place among the tracked temporary files, or -1 */
} outfile;

/* open a temporary file for path (mode 0666 less the umask like fopen, or the existing
 * target's permissions); nonzero with a message in err (errlen bytes) when it cannot */
int outfile_open(outfile *o, const char *path, char *err, size_t errlen);
/* flush and close: every byte is in the temporary file, which stays (outfile_publish puts
 * it in place, outfile_abort removes it); on an error the temporary file is removed and err
 * says why */
int outfile_finish(outfile *o, char *err, size_t errlen);
/* rename a finished temporary file over its target */
int outfile_publish(outfile *o, char *err, size_t errlen);
/* outfile_finish then outfile_publish */
int outfile_commit(outfile *o, char *err, size_t errlen);
/* a file of a collection: committed when staged is NULL, else finished and handed over in
 * *staged, for the caller to publish with the others or abort */
int outfile_end(outfile *o, outfile *staged, char *err, size_t errlen);
/* give up: remove the temporary file (open or finished), leave the target as it was */
void outfile_abort(outfile *o);

/* another temporary file to remove if a signal ends the run (a compiler's output), and the
 * process writing it (0: none) to end then too; the slot for outfile_untrack, or -1 */
int outfile_track(const char *path, pid_t pid);
void outfile_untrack(int slot);
/* the command-line programs' handlers: SIGINT, SIGTERM, SIGHUP and SIGQUIT remove the
 * tracked temporary files and end the run by the same signal; SIGXFSZ is ignored, so that
 * a write past the file size limit (ulimit -f) fails with EFBIG and is reported */
void outfile_on_signals(void);

#endif

/* rendezvous.c — records sent to other ranks through MPI all-to-alls, and answers returned in
 * the order asked: the mechanism of every rendezvous of the distributed runs (distribute.c's
 * node numbering, read_dist.c's parallel reader). A rank that failed already takes part with
 * empty messages; where any rank cannot receive, no rank exchanges and every one learns it
 * (the callers' "bad" flag), so that no rank is left waiting in a collective. */
#include "parallel_int.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

void *lg_box_add(lg_box *b, int dest, int *bad) {
  if (*bad) return NULL;
  if (b->n == b->cap) {
    long c = b->cap ? 2 * b->cap : 1024;
    int *d = realloc(b->dest, sizeof(int) * (size_t)c);
    if (d) b->dest = d;
    char *x = d ? realloc(b->data, b->rec * (size_t)c) : NULL;
    if (!x) { *bad = 1; return NULL; }
    b->data = x;
    b->cap = c;
  }
  b->dest[b->n] = dest;
  return memset(b->data + b->rec * (size_t)b->n++, 0, b->rec);
}

void lg_box_free(lg_box *b) {
  free(b->dest);
  free(b->data);
  b->dest = NULL;
  b->data = NULL;
  b->n = b->cap = 0;
}

static MPI_Datatype rec_type(size_t rec) {
  MPI_Datatype t;
  (void)MPI_Type_contiguous((int)rec, MPI_BYTE, &t);
  (void)MPI_Type_commit(&t);
  return t;
}

/* an all-to-all of rec-byte records: cnt[r] of them for rank r from send, rcnt[r] from rank
 * r into the returned buffer (*nrecv in all, rank by rank); NULL sets *bad. Collective: a rank
 * that failed already sends nothing, and still takes part; where any rank cannot (counts over
 * 2^31, no memory for what it receives) no rank exchanges and every one is bad */
static char *alltoall(const char *send, size_t rec, int *cnt, int *rcnt, long *nrecv, int *bad) {
  int P = lg_mpi_size();
  if (*bad) memset(cnt, 0, sizeof(int) * (size_t)P);
  *nrecv = 0;
  int *sd = malloc(sizeof(int) * 2 * (size_t)P), *rd = sd ? sd + P : NULL;
  int fail = !sd;
  if (MPI_Alltoall(cnt, 1, MPI_INT, rcnt, 1, MPI_INT, PETSC_COMM_WORLD) != MPI_SUCCESS) fail = 1;
  long st = 0, rt = 0;
  for (int r = 0; !fail && r < P; r++) {
    sd[r] = (int)st;
    rd[r] = (int)rt;
    st += cnt[r];
    rt += rcnt[r];
  }
  char *recv = fail || st > INT32_MAX || rt > INT32_MAX ? NULL : malloc(rec * (size_t)rt + 1);
  int f = !recv, anyf = 1;
  if (MPI_Allreduce(&f, &anyf, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD) != MPI_SUCCESS) anyf = 1;
  if (anyf) {
    free(recv);
    free(sd);
    *bad = 1;
    return NULL;
  }
  MPI_Datatype t = rec_type(rec);
  if (MPI_Alltoallv((void *)send, cnt, sd, t, recv, rcnt, rd, t, PETSC_COMM_WORLD) != MPI_SUCCESS) {
    free(recv);
    recv = NULL;
    *bad = 1;
    rt = 0;
  }
  (void)MPI_Type_free(&t);
  free(sd);
  *nrecv = rt;
  return recv;
}

/* a box sent: its records sorted by rank (*order[k]: the box index of the k-th sent, so that
 * answers in the order received map back), cnt per rank; the records received */
char *lg_box_send(lg_box *b, int *cnt, int *rcnt, long **order, long *nrecv, int *bad) {
  int P = lg_mpi_size();
  long *at = calloc((size_t)P + 1, sizeof(long)), *ord = malloc(sizeof(long) * ((size_t)b->n + 1));
  char *sorted = malloc(b->rec * (size_t)b->n + 1);
  if (!at || !ord || !sorted) *bad = 1;
  for (int r = 0; r < P; r++) cnt[r] = 0;
  for (long i = 0; !*bad && i < b->n; i++) cnt[b->dest[i]]++;
  for (int r = 1; !*bad && r < P; r++) at[r] = at[r - 1] + cnt[r - 1];
  for (long i = 0; !*bad && i < b->n; i++) {
    long k = at[b->dest[i]]++;
    ord[k] = i;
    memcpy(sorted + b->rec * (size_t)k, b->data + b->rec * (size_t)i, b->rec);
  }
  /* the box's own copy goes before the exchange (b->n stays): one copy less at the peak */
  free(b->data);
  free(b->dest);
  b->data = NULL;
  b->dest = NULL;
  char *recv = alltoall(sorted, b->rec, cnt, rcnt, nrecv, bad);
  free(at);
  free(sorted);
  if (order) *order = ord;
  else free(ord);
  return recv;
}

/* answers (rec bytes each) to records received with the counts rcnt, back to their senders,
 * who sent cnt: the k-th returned answers their k-th sent record */
char *lg_reply(const char *ans, size_t rec, int *rcnt, int *cnt, int *bad) {
  int P = lg_mpi_size();
  int *c1 = malloc(sizeof(int) * 2 * (size_t)P);
  if (!c1) { *bad = 1; return NULL; }
  memcpy(c1, rcnt, sizeof(int) * (size_t)P);
  long n;
  char *back = alltoall(ans, rec, c1, c1 + P, &n, bad);
  for (int r = 0; !*bad && r < P; r++)
    if (c1[P + r] != cnt[r]) *bad = 1;
  free(c1);
  return back;
}

/* gmsh_layout.c — a Gmsh MSH file's layout, for reading it in parts (read_dist.c): one pass
 * over its lines through a 4 MB buffer finds its sections, the MSH 4 entity blocks of its
 * nodes and elements, and the file offsets and line numbers where each of nparts even runs
 * of nodes and elements starts (mesh_gmsh_layout), without parsing them; the layout packed
 * into bytes and back, to be broadcast. gmsh.c's part reader (mesh_gmsh_read_part) parses a
 * run from there. */
#include "io.h"

#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* the layout's line reader: a file's lines through one buffer, each up to LR_CHUNK bytes */
#define LR_CHUNK ((size_t)4 << 20)
typedef struct {
  int fd, eof;
  char *buf;
  size_t lo, hi;
  long long off, line; /* file offset of buf[lo], lines returned so far */
} lreader;

/* the next line (*s, *n bytes without its newline, from file offset *off, line r->line):
 * 1, or 0 at the end, -1 on a read error or a line longer than the buffer */
static int lr_next(lreader *r, const char **s, size_t *n, long long *off) {
  for (;;) {
    char *nl = r->hi > r->lo ? memchr(r->buf + r->lo, '\n', r->hi - r->lo) : NULL;
    if (nl || (r->eof && r->hi > r->lo)) {
      size_t len = nl ? (size_t)(nl - (r->buf + r->lo)) : r->hi - r->lo, adv = len + (nl != NULL);
      *s = r->buf + r->lo;
      *n = len;
      *off = r->off;
      r->lo += adv;
      r->off += (long long)adv;
      r->line++;
      return 1;
    }
    if (r->eof) return 0;
    if (r->lo) {
      memmove(r->buf, r->buf + r->lo, r->hi - r->lo);
      r->hi -= r->lo;
      r->lo = 0;
    }
    if (r->hi == LR_CHUNK) return -1;
    ssize_t got = read(r->fd, r->buf + r->hi, LR_CHUNK - r->hi);
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) return -1;
    if (got == 0) r->eof = 1;
    else r->hi += (size_t)got;
  }
}

/* the line without surrounding white space: empty, or at most max integers read into v
 * (returns how many; -1 when something else is on the line) */
static int line_ints(const char *s, size_t n, long long *v, int max) {
  char tmp[256];
  while (n && isspace((unsigned char)s[n - 1])) n--;
  while (n && isspace((unsigned char)*s)) { s++; n--; }
  if (n >= sizeof tmp) return -1;
  memcpy(tmp, s, n);
  tmp[n] = 0;
  char *p = tmp;
  int k = 0;
  for (;;) {
    while (isspace((unsigned char)*p)) p++;
    if (!*p) return k;
    if (k == max) return -1;
    char *end;
    errno = 0;
    v[k] = strtoll(p, &end, 10);
    if (end == p || errno || (*end && !isspace((unsigned char)*end))) return -1;
    k++;
    p = end;
  }
}
static int blank(const char *s, size_t n) {
  for (size_t i = 0; i < n; i++)
    if (!isspace((unsigned char)s[i])) return 0;
  return 1;
}
static int is_word(const char *s, size_t n, const char *w) {
  while (n && isspace((unsigned char)s[n - 1])) n--;
  while (n && isspace((unsigned char)*s)) { s++; n--; }
  return n == strlen(w) && !memcmp(s, w, n);
}

typedef struct {
  lreader r;
  gmsh_layout *L;
  const char *s;
  size_t n;
  long long off;
} lscan;

/* the next non-blank line: 1, or 0 (the reason in L->why) */
static int ls_line(lscan *S) {
  int rc;
  while ((rc = lr_next(&S->r, &S->s, &S->n, &S->off)) == 1)
    if (!blank(S->s, S->n)) return 1;
  snprintf(S->L->why, sizeof S->L->why, rc < 0 ? "a read error or a line over 4 MB" : "the file ends inside a section");
  return 0;
}


/* `count` item lines of a block from item `first` on: their span, and the positions of the
 * runs that start there (*k: the next run to place; b: the second span of MSH 4 nodes) */
static int scan_items(lscan *S, long long first, long long count, long long total, int *k, gmsh_pos *pos, int second,
                      gmsh_span *sp) {
  int P = S->L->nparts;
  sp->off = sp->end = S->r.off;
  sp->line = S->r.line + 1;
  for (long long j = 0; j < count; j++) {
    if (!ls_line(S)) return 1;
    if (!j) { sp->off = S->off; sp->line = S->r.line; }
    while (*k <= P && gmsh_run_start(total, P, *k) == first + j) {
      if (second) { pos[*k].boff = S->off; pos[*k].bline = S->r.line; }
      else { pos[*k].aoff = S->off; pos[*k].aline = S->r.line; }
      (*k)++;
    }
    sp->end = S->r.off;
  }
  return 0;
}

static int grow_blocks(gmsh_block **b, int n, int *cap) {
  if (n < *cap) return 0;
  if (n > 1 << 24) return 1;
  int c = *cap ? 2 * *cap : 64;
  gmsh_block *q = realloc(*b, sizeof(gmsh_block) * (size_t)c);
  if (!q) return 1;
  *b = q;
  *cap = c;
  return 0;
}

/* $Nodes (elems 0) or $Elements (1), after its name's line */
static int scan_section(lscan *S, int elems) {
  gmsh_layout *L = S->L;
  long long h[4];
  int P = L->nparts, cap = 0, k = 0, k2 = 0;
  gmsh_block **bl = elems ? &L->eb : &L->nb;
  int *nbl = elems ? &L->neb : &L->nnb;
  gmsh_pos *pos = calloc((size_t)P + 1, sizeof(gmsh_pos));
  if (!pos) { snprintf(L->why, sizeof L->why, "out of memory"); return 1; }
  if (elems) L->ep = pos;
  else L->np = pos;
  if (!ls_line(S)) return 1;
  long long nb = 1, total;
  if (L->version == 2) {
    if (line_ints(S->s, S->n, h, 1) != 1 || h[0] < 0) { snprintf(L->why, sizeof L->why, "an unusual section header"); return 1; }
    total = h[0];
  } else {
    if (line_ints(S->s, S->n, h, 4) != 4 || h[0] < 0 || h[1] < 0) { snprintf(L->why, sizeof L->why, "an unusual section header"); return 1; }
    nb = h[0];
    total = h[1];
  }
  long long seen = 0;
  for (long long b = 0; b < nb; b++) {
    if (grow_blocks(bl, *nbl, &cap)) { snprintf(L->why, sizeof L->why, "too many blocks"); return 1; }
    gmsh_block *B = &(*bl)[*nbl];
    memset(B, 0, sizeof *B);
    B->type = -1;
    B->first = seen;
    if (L->version == 2) B->count = total;
    else {
      if (!ls_line(S)) return 1;
      if (line_ints(S->s, S->n, h, 4) != 4 || h[3] < 0) { snprintf(L->why, sizeof L->why, "an unusual block header"); return 1; }
      B->edim = (int)h[0];
      B->etag = h[1];
      if (elems) B->type = (int)h[2];
      else B->par = (int)h[2];
      B->count = h[3];
    }
    if (B->count > total - seen) { snprintf(L->why, sizeof L->why, "blocks beyond the section's count"); return 1; }
    (*nbl)++;
    if (scan_items(S, seen, B->count, total, &k, pos, 0, &B->a)) return 1;
    B->b = B->a;
    if (!elems && L->version == 4 && scan_items(S, seen, B->count, total, &k2, pos, 1, &B->b)) return 1;
    seen += B->count;
  }
  if (seen != total) { snprintf(L->why, sizeof L->why, "blocks that do not add up to the section's count"); return 1; }
  if (!ls_line(S)) return 1;
  if (!is_word(S->s, S->n, elems ? "$EndElements" : "$EndNodes")) { snprintf(L->why, sizeof L->why, "more lines than items"); return 1; }
  /* the runs that start at the end (more parts than items) */
  for (; k <= P; k++) { pos[k].aoff = pos[k].boff = S->r.off; pos[k].aline = pos[k].bline = S->r.line; }
  if (elems) L->nelems = total;
  else L->nnodes = total;
  return 0;
}

int mesh_gmsh_layout(const char *path, int nparts, gmsh_layout *L) {
  memset(L, 0, sizeof *L);
  L->nparts = nparts;
  lscan S = {{-1, 0, NULL, 0, 0, 0, 0}, L, NULL, 0, 0};
  struct stat st;
  int have_nodes = 0, have_elems = 0;
  if (nparts < 1) { snprintf(L->why, sizeof L->why, "no parts"); return 0; }
  S.r.fd = open(path, O_RDONLY | O_CLOEXEC);
  if (S.r.fd < 0 || fstat(S.r.fd, &st) || !S_ISREG(st.st_mode)) {
    snprintf(L->why, sizeof L->why, "not a regular file");
    goto out;
  }
  if (!(S.r.buf = malloc(LR_CHUNK))) { snprintf(L->why, sizeof L->why, "out of memory"); goto out; }
  for (;;) {
    int rc = lr_next(&S.r, &S.s, &S.n, &S.off);
    if (rc < 0) { snprintf(L->why, sizeof L->why, "a read error or a line over 4 MB"); goto out; }
    if (!rc) break;
    if (blank(S.s, S.n)) continue;
    size_t a = 0, n = S.n;
    while (isspace((unsigned char)S.s[a])) a++;
    while (n > a && isspace((unsigned char)S.s[n - 1])) n--;
    if (S.s[a] != '$') { snprintf(L->why, sizeof L->why, "data outside a section"); goto out; }
    char name[80];
    snprintf(name, sizeof name, "%.*s", (int)(n - a > 70 ? 70 : n - a), S.s + a);
    int nodes = !strcmp(name, "$Nodes"), elems = !strcmp(name, "$Elements");
    if (nodes || elems) {
      if (!L->version || (nodes ? have_nodes : have_elems)) {
        snprintf(L->why, sizeof L->why, "%s before $MeshFormat or twice", name);
        goto out;
      }
      if (nodes) have_nodes = 1;
      else have_elems = 1;
      if (scan_section(&S, elems)) goto out;
      continue;
    }
    /* a small section: its span, read by every process */
    if (L->nsmall == GMSH_MAX_SMALL) { snprintf(L->why, sizeof L->why, "more than %d other sections", GMSH_MAX_SMALL); goto out; }
    gmsh_span *sp = &L->small[L->nsmall++];
    sp->off = S.off;
    sp->line = S.r.line;
    char end[96];
    snprintf(end, sizeof end, "$End%s", name + 1);
    int fmt = !strcmp(name, "$MeshFormat"), first = 1;
    for (;;) {
      if (!ls_line(&S)) goto out;
      if (is_word(S.s, S.n, end)) break;
      if (fmt && first) {
        char v[16];
        size_t b = 0;
        while (b < S.n && isspace((unsigned char)S.s[b])) b++;
        snprintf(v, sizeof v, "%.*s", (int)(S.n - b > 15 ? 15 : S.n - b), S.s + b);
        L->version = !strncmp(v, "4.1", 3) ? 4 : v[0] == '2' ? 2 : 0;
        if (!L->version) { snprintf(L->why, sizeof L->why, "MSH version %s", v); goto out; }
      }
      first = 0;
    }
    sp->end = S.r.off;
    if (sp->end - sp->off > (64LL << 20)) { snprintf(L->why, sizeof L->why, "a section %s of over 64 MB", name); goto out; }
  }
  if (!have_nodes || !have_elems) { snprintf(L->why, sizeof L->why, "no $Nodes or no $Elements"); goto out; }
  L->ok = 1;
out:
  if (S.r.fd >= 0) close(S.r.fd);
  free(S.r.buf);
  return L->ok;
}

void mesh_gmsh_layout_free(gmsh_layout *L) {
  free(L->nb); free(L->eb); free(L->np); free(L->ep);
  L->nb = L->eb = NULL;
  L->np = L->ep = NULL;
}

int mesh_gmsh_layout_pack(const gmsh_layout *L, char **buf, size_t *len) {
  size_t P = (size_t)L->nparts + 1;
  size_t n = sizeof *L + sizeof(gmsh_block) * ((size_t)L->nnb + (size_t)L->neb) + 2 * P * sizeof(gmsh_pos);
  char *b = malloc(n), *p = b;
  if (!b) return 1;
  memcpy(p, L, sizeof *L); p += sizeof *L;
  if (L->nnb) memcpy(p, L->nb, sizeof(gmsh_block) * (size_t)L->nnb);
  p += sizeof(gmsh_block) * (size_t)L->nnb;
  if (L->neb) memcpy(p, L->eb, sizeof(gmsh_block) * (size_t)L->neb);
  p += sizeof(gmsh_block) * (size_t)L->neb;
  if (L->np) memcpy(p, L->np, P * sizeof(gmsh_pos));
  else memset(p, 0, P * sizeof(gmsh_pos));
  p += P * sizeof(gmsh_pos);
  if (L->ep) memcpy(p, L->ep, P * sizeof(gmsh_pos));
  else memset(p, 0, P * sizeof(gmsh_pos));
  *buf = b;
  *len = n;
  return 0;
}

int mesh_gmsh_layout_unpack(const char *buf, size_t len, gmsh_layout *L) {
  if (len < sizeof *L) return 1;
  memcpy(L, buf, sizeof *L);
  L->nb = L->eb = NULL;
  L->np = L->ep = NULL;
  size_t P = (size_t)L->nparts + 1;
  if (L->nparts < 1 || L->nnb < 0 || L->neb < 0 ||
      len != sizeof *L + sizeof(gmsh_block) * ((size_t)L->nnb + (size_t)L->neb) + 2 * P * sizeof(gmsh_pos))
    return 1;
  L->nb = malloc(sizeof(gmsh_block) * ((size_t)L->nnb + 1));
  L->eb = malloc(sizeof(gmsh_block) * ((size_t)L->neb + 1));
  L->np = malloc(sizeof(gmsh_pos) * P);
  L->ep = malloc(sizeof(gmsh_pos) * P);
  if (!L->nb || !L->eb || !L->np || !L->ep) { mesh_gmsh_layout_free(L); return 1; }
  const char *p = buf + sizeof *L;
  memcpy(L->nb, p, sizeof(gmsh_block) * (size_t)L->nnb); p += sizeof(gmsh_block) * (size_t)L->nnb;
  memcpy(L->eb, p, sizeof(gmsh_block) * (size_t)L->neb); p += sizeof(gmsh_block) * (size_t)L->neb;
  memcpy(L->np, p, sizeof(gmsh_pos) * P); p += sizeof(gmsh_pos) * P;
  memcpy(L->ep, p, sizeof(gmsh_pos) * P);
  return 0;
}

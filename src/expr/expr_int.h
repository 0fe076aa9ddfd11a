/* expr_int.h — what the files of src/expr share beyond expr.h: the memo map (node id ->
 * node), the post-order walk over a DAG, and small node tests. Not part of the API. */
#ifndef LUGAL_EXPR_INT_H
#define LUGAL_EXPR_INT_H

#include "expr.h"

#include <stdlib.h>

typedef struct {
  int64_t key;
  expr *val;
} memo_entry;
typedef struct {
  size_t cap, n;
  memo_entry *e; /* val == NULL: empty */
} memo_map;

static inline uint64_t mix64(uint64_t h) {
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdull;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ull;
  h ^= h >> 33;
  return h;
}

static inline expr *memo_get(memo_map *m, int64_t key) {
  if (!m->cap) return NULL;
  size_t h = mix64((uint64_t)key) & (m->cap - 1);
  while (m->e[h].val) {
    if (m->e[h].key == key) return m->e[h].val;
    h = (h + 1) & (m->cap - 1);
  }
  return NULL;
}

int expr_memo_put(memo_map *m, int64_t key, expr *val);
static inline void memo_free(memo_map *m) { free(m->e); m->e = NULL; m->cap = m->n = 0; }

/* post-order over the DAG under root with an explicit stack (no depth recursion): visit(e)
 * runs once per node after all its children, in the order a recursive walk would; a child
 * for which skip(ud, child) is true is neither entered nor visited */
typedef int (*post_visit)(void *ud, expr *e);
int expr_post_order(expr_ctx *c, expr *root, memo_map *seen, post_visit visit, post_visit skip, void *ud);

/* the context's memo of derivatives (diff.c): key = node id * 2^24 + variable */
memo_map *expr_ctx_dmemo(expr_ctx *c);

static inline int is_const(const expr *e, double v) { return e && e->kind == E_CONST && e->value == v; }

#endif

/* env.c — the environment of a run (process.h): made and freed with the symbolic context
 * and the JIT, and the errors every fallible function of the assembly layer reports in it,
 * its own and PETSc's. */
#include "process.h"

#include <petscsys.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void lg_seterr(lg_env *env, const char *fmt, ...) {
  char tmp[LG_ERRLEN];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(tmp, sizeof tmp, fmt, ap);
  va_end(ap);
  /* element loops' threads may report at once (lg_assemble_chunks): one whole message */
#ifdef _OPENMP
#pragma omp critical(lg_seterr)
#endif
  memcpy(env->err, tmp, sizeof tmp);
}

lg_env *lg_env_new(const char *tcc_libdir) {
  lg_env *env = calloc(1, sizeof *env);
  if (!env) return NULL;
  env->c = expr_ctx_new();
  env->jit = jit_new(JIT_AUTO, tcc_libdir);
  env->pcache.prev = env->pcache.next = &env->pcache;
  if (!env->c || !env->jit) { lg_env_free(env); return NULL; }
  return env;
}

void lg_env_free(lg_env *env) {
  if (!env) return;
  for (int i = 0; i < LG_INTEGRATE_KEEP; i++) kernel_release(&env->kept[i].k);
  /* groups whose kernels outlive the environment (none when objects are freed in order) */
  while (env->pcache.next && env->pcache.next != &env->pcache) {
    kernel_pcache_group *g = env->pcache.next;
    env->pcache.next = g->next;
    free(g->v);
    free(g);
  }
  expr_ctx_free(env->c);
  jit_free(env->jit);
  free(env);
}

int lg_petsc_fail(lg_env *env, int ierr, const char *what) {
  const char *text = NULL;
  PetscErrorMessage((PetscErrorCode)ierr, &text, NULL);
  lg_seterr(env, "%s failed: %s", what, text ? text : "PETSc error");
  return 1;
}

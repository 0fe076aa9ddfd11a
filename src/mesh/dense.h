/* dense.h — small dense symmetric matrices (libc and libm only): the cyclic Jacobi
 * eigenvalue method, shared by the untangler's projected Hessians (src/mesh) and the
 * Gauss–Jacobi quadrature rules (Golub–Welsch, src/assemble/fem.c). */
#ifndef LUGAL_DENSE_H
#define LUGAL_DENSE_H

/* The eigen-decomposition of the symmetric n×n matrix a (row-major): a becomes diagonal
 * (its eigenvalues), the columns of v (n×n) its eigenvectors. Sweeps of rotations stop when
 * the squared off-diagonal sum is below off_abs or at most off_rel times the squared
 * diagonal's (or after 100 sweeps); entries below 1e-300 are not rotated. */
void dense_sym_eigen(int n, double *a, double *v, double off_abs, double off_rel);

#endif

/* dense.h — small dense symmetric matrices (libc and libm only): the cyclic Jacobi
 * eigenvalue method, shared by the untangler's projected Hessians (src/mesh) and the
 * Gauss–Jacobi quadrature rules (Golub–Welsch, src/assemble/fem/fem.c), and a closed form for 3×3
 * (the smoother's per-corner singular values and scaling modes). */
#ifndef LUGAL_DENSE_H
#define LUGAL_DENSE_H

/* The eigen-decomposition of the symmetric n×n matrix a (row-major): a becomes diagonal
 * (its eigenvalues), the columns of v (n×n) its eigenvectors. Sweeps of rotations stop when
 * the squared off-diagonal sum is below off_abs or at most off_rel times the squared
 * diagonal's (or after 100 sweeps); entries below 1e-300 are not rotated. The sums are of
 * squares: with entries beyond 1e±150 they overflow or underflow and the sweeps stop early
 * (dense_sym_eigen3 scales first). */
void dense_sym_eigen(int n, double *a, double *v, double off_abs, double off_rel);

/* The same for a symmetric 3×3 matrix a (row-major, kept), in closed form: the eigenvalue
 * farthest from the other two from the characteristic cubic's trigonometric solution, its
 * eigenvector as the largest cross product of two rows of a − λI, the other two by one
 * Jacobi rotation in its complement (a multiple of I to rounding gets the axes). w the
 * eigenvalues, as the Rayleigh quotients of those vectors, in ascending order, the columns of
 * v the vectors (orthonormal to rounding). Backward stable: |a v_k − w_k v_k| is a rounding
 * error of |a|, for repeated and nearly repeated eigenvalues too. */
void dense_sym_eigen3(const double *a, double *w, double *v);

#endif

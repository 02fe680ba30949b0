/* pca.h — the symmetric 3x3 eigen solver behind PCA normals.
 *
 * Eigenvalues come from the closed-form trigonometric solution of the characteristic cubic, in
 * double, on the matrix scaled to unit magnitude; the eigenvector of the smallest eigenvalue is
 * the largest cross product of two rows of (A - lambda I), which is accurate whenever that
 * eigenvalue is separated from the others. When it is not (a line-like or isotropic
 * neighbourhood, where the normal is undefined anyway) any vector of its eigenspace is returned. */
#pragma once
#include <stdint.h>

/* A symmetric 3x3 matrix as its six distinct entries. */
typedef struct prep_sym3 {
    double xx, xy, xz, yy, yz, zz;
} prep_sym3;

/* prep_sym3_eigenvalues: the three eigenvalues of a, ascending, in ev. */
void prep_sym3_eigenvalues(const prep_sym3 *a, double ev[3]);

/* prep_sym3_smallest: writes the unit eigenvector of a's smallest eigenvalue to v and returns that
 * eigenvalue. A zero matrix (or a multiple of the identity) gives v = (0, 0, 1). */
double prep_sym3_smallest(const prep_sym3 *a, double v[3]);

/* prep_pca_normal: the unit normal (unoriented) of the m points of pos whose indices are
 * self followed by the nbr[0..k-1]: the eigenvector of the smallest eigenvalue of their covariance.
 * Coordinates are taken relative to pos[self] in double. Also returns the curvature
 * lambda_min / (l0 + l1 + l2) in *curv when curv is not NULL. */
void prep_pca_normal(const float *pos, uint32_t self, const uint32_t *nbr, int k, float n[3],
                     float *curv);

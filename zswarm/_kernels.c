/* Compiled loops for the batched engine's hot spots, loaded with ctypes (zswarm/kernels.py).
 *
 * Each function does the operations of the numpy code it replaces, in the same order, so that
 * a run gives the same numbers with or without it (tests/unit/test_kernels.py compares them
 * bit for bit):
 *
 *  - rigid_step: world/dynamics.py RigidBodies.step for isotropic inertias (the implicit
 *    midpoint rule on SO(3) x R^3, Rodrigues' formula of zswarm/so3.py exp_batch).  numpy's
 *    stacked 3x3 products (matmul) sum over the inner index 0, 1, 2 as a chain of fused
 *    multiply-adds on this machine's x86-64 (its AVX2/AVX-512 loops), so mm3 does too; its
 *    elementwise operations round each operation, and einsum("ij,ij->i") sums the three
 *    squares as (x² + z²) + y².  J_inv must be diagonal (world/dynamics.py checks): then
 *    J_inv tau is exact in any order.
 *  - exp_batch: zswarm/so3.py exp_batch, Rodrigues' formula for a stack of rotation vectors.
 *  - flow_xi: agent/algorithms/attitude_sync_terms.py flow_xi, Heun's method on (5.21) in n
 *    sub-steps for each of M draws.
 *  - flow_aux: the velocity-free law's (Q_i, zeta_i) filter (attitude_sync_velocity_free.py), Heun's
 *    method on SO(3) x R in n sub-steps for each of M draws.  Python's float arithmetic and numpy's ufuncs round every
 *    operation; sin and cos are the C library's, as Python's math and numpy call them.
 *
 * Built with -ffp-contract=off: the compiler must not fuse a*b + c on its own (that would
 * change the last bit against numpy); the fused products above are written out as fma().
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>

/* The loops that multiply matrices come in two builds chosen at load time (GCC's target_clones): with
 * the FMA instructions where the CPU has them, and a default one where fma() is the C library's call.
 * fma() rounds once either way, so both give the same bits; the first is ~3x faster (measured on the
 * velocity-free filter, where the library call was most of the time). */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define FMA_CLONES __attribute__((target_clones("fma", "default")))
#else
#define FMA_CLONES
#endif

static inline void mm3(const double *a, const double *b, double *c)
{
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            c[3 * i + k] = fma(a[3 * i + 2], b[6 + k], fma(a[3 * i + 1], b[3 + k], a[3 * i] * b[k]));
}

/* Rodrigues' formula of one rotation vector W into E, as zswarm/so3.py exp_batch computes it. */
static inline void rodrigues(const double W[3], double E[9])
{
    const double t2 = (W[0] * W[0] + W[2] * W[2]) + W[1] * W[1]; /* einsum("ij,ij->i")'s order */
    double a, b;
    if (t2 < 1e-8) {
        a = 1.0 - t2 / 6.0;
        b = 0.5 - t2 / 24.0;
    } else {
        const double s = sqrt(t2);
        a = sin(s) / s;
        b = (1.0 - cos(s)) / t2;
    }
    const double K[9] = {0.0, -W[2], W[1], W[2], 0.0, -W[0], -W[1], W[0], 0.0};
    double KK[9];
    mm3(K, K, KK);
    for (int q = 0; q < 9; q++)
        E[q] = ((q % 4 == 0 ? 1.0 : 0.0) + a * K[q]) + b * KK[q];
}

/* zswarm/so3.py exp_batch: n rotation vectors W (n,3) -> E (n,3,3). */
FMA_CLONES
void exp_batch(size_t n, const double *W, double *E)
{
    for (size_t m = 0; m < n; m++)
        rodrigues(W + 3 * m, E + 9 * m);
}

/* n bodies: R (n,3,3) and w (n,3) advanced by h under the torques tau (n,3) held over the step,
 * into R_out and w_out; J_inv (n,3,3) the inverse inertias (isotropic: J = jI). */
FMA_CLONES
void rigid_step(size_t n, const double *R, const double *w, const double *J_inv, const double *tau, double h, double *R_out, double *w_out)
{
    const double hh = 0.5 * h;
    for (size_t m = 0; m < n; m++) {
        const double *Rm = R + 9 * m, *wm = w + 3 * m;
        const double *J = J_inv + 9 * m, *t = tau + 3 * m;
        double wb[3], W[3];
        for (int r = 0; r < 3; r++)
            wb[r] = wm[r] + hh * ((J[3 * r] * t[0] + J[3 * r + 1] * t[1]) + J[3 * r + 2] * t[2]);
        for (int r = 0; r < 3; r++) {
            w_out[3 * m + r] = 2.0 * wb[r] - wm[r];
            W[r] = h * wb[r];
        }
        double E[9];
        rodrigues(W, E);
        mm3(Rm, E, R_out + 9 * m);
    }
}

/* M draws of xi advanced in place by dt in n Heun sub-steps of
 * xi' = -k_xi (gamma xi + 2 (a + b sin xi + q (1 - cos xi))), (a, b, q) going linearly from
 * (a0, b0, q0) to (a1, b1, q1) over the interval. */
void flow_xi(size_t M, const double *a0v, const double *b0v, const double *q0v, const double *a1v, const double *b1v, const double *q1v,
             double *xv, double dt, double k_xi, double gamma, long n)
{
    const double h = dt / (double)n, two_k = 2.0 * k_xi, kg = k_xi * gamma;
    for (size_t i = 0; i < M; i++) {
        double xi = xv[i];
        const double a0 = a0v[i], b0 = b0v[i], q0 = q0v[i];
        const double da = a1v[i] - a0, db = b1v[i] - b0, dq = q1v[i] - q0;
        double f = -kg * xi - two_k * ((a0 + b0 * sin(xi)) + q0 * (1.0 - cos(xi)));
        for (long m = 0; m < n; m++) {
            const double s1 = (double)(m + 1) / (double)n;
            const double a1 = a0 + s1 * da, b1 = b0 + s1 * db, q1 = q0 + s1 * dq;
            const double x1 = xi + h * f;
            const double f1 = -kg * x1 - two_k * ((a1 + b1 * sin(x1)) + q1 * (1.0 - cos(x1)));
            xi = xi + 0.5 * h * (f + f1);
            f = -kg * xi - two_k * ((a1 + b1 * sin(xi)) + q1 * (1.0 - cos(xi)));
        }
        xv[i] = xi;
    }
}

/* flow_xi of one draw (a ctypes call with numbers: sim's path, one agent and edge at a time). */
double flow_xi_one(double a0, double b0, double q0, double a1, double b1, double q1, double xi, double dt, double k_xi, double gamma, long n)
{
    flow_xi(1, &a0, &b0, &q0, &a1, &b1, &q1, &xi, dt, k_xi, gamma, n);
    return xi;
}

/* (k_Q h_i, zeta') of agent_sync_velocity_free _Rates for one draw: Z = Ra(zeta, u) from K = [u]^x and
 * K2 = K K, p = psi((A Qt) Z), k_Q Z p and -k_zeta (gamma zeta + p . 2u), the products Z p and p . 2u
 * summed (x0 y0 + x1 y1) + x2 y2. */
static inline void aux_rates(const double Qt[9], double z, const double A[9], const double K[9], const double K2[9], const double u2[3], double k_Q,
                             double nk_zeta, double gamma, double kh[3], double *zd)
{
    const double s = sin(z), c = 1.0 - cos(z);
    double Z[9], X[9], Y[9];
    for (int q = 0; q < 9; q++)
        Z[q] = ((q % 4 == 0 ? 1.0 : 0.0) + s * K[q]) + c * K2[q];
    mm3(A, Qt, X);
    mm3(X, Z, Y);
    const double p0 = (Y[7] - Y[5]) * 0.5, p1 = (Y[2] - Y[6]) * 0.5, p2 = (Y[3] - Y[1]) * 0.5;
    for (int r = 0; r < 3; r++)
        kh[r] = k_Q * ((Z[3 * r] * p0 + Z[3 * r + 1] * p1) + Z[3 * r + 2] * p2);
    *zd = nk_zeta * (gamma * z + ((p0 * u2[0] + p1 * u2[1]) + p2 * u2[2]));
}

/* agent/algorithms/attitude_sync_velocity_free.py flow_aux's sub-steps for M draws: Heun's method on
 * (Qt, zeta) (thesis (5.14), (5.23)), Qt (M,3,3) and zeta (M) advanced in place by n sub-steps of h;
 * sub-step m reads the body rate table[rows[m]] (table (rows, M, 3)). */
FMA_CLONES
void flow_aux(size_t M, long n, double *Qt_all, double *z_all, const double *table, const int64_t *rows, double h, const double *A, const double *K,
              const double *K2, const double *u2, double k_Q, double k_zeta, double gamma)
{
    const double hh = 0.5 * h, nk = -k_zeta;
    for (size_t m = 0; m < M; m++) {
        double *Qt = Qt_all + 9 * m;
        double z = z_all[m], z1, z2, kh1[3], kh2[3], v1[3], W[3], E[9], Q1[9], Qn[9];
        aux_rates(Qt, z, A, K, K2, u2, k_Q, nk, gamma, kh1, &z1);
        for (long k = 0; k < n; k++) {
            const double *w = table + 3 * ((size_t)rows[k] * M + m);
            for (int r = 0; r < 3; r++) {
                v1[r] = w[r] - kh1[r];
                W[r] = h * v1[r];
            }
            rodrigues(W, E);
            mm3(Qt, E, Q1);
            aux_rates(Q1, z + h * z1, A, K, K2, u2, k_Q, nk, gamma, kh2, &z2);
            for (int r = 0; r < 3; r++)
                W[r] = hh * ((v1[r] + w[r]) - kh2[r]);
            rodrigues(W, E);
            mm3(Qt, E, Qn);
            for (int q = 0; q < 9; q++)
                Qt[q] = Qn[q];
            z = z + hh * (z1 + z2);
            aux_rates(Qt, z, A, K, K2, u2, k_Q, nk, gamma, kh1, &z1);
        }
        z_all[m] = z;
    }
}

/* An importable module, so that zswarm/kernels.py finds the library where Python finds it. */
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernels", "zswarm's compiled loops (called through ctypes: zswarm/kernels.py)", -1, NULL};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }

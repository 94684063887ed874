/* Compiled loops for the batched engine's and sim's hot spots, a Python extension module called from
 * zswarm/math/kernels.py (its functions at the end: arrays through the buffer protocol, checked).
 *
 * Each function does the operations of the numpy code it replaces, in the same order, so that
 * a run gives the same numbers with or without it (tests/unit/test_kernels.py compares them
 * bit for bit):
 *
 *  - rigid_step: world/dynamics.py RigidBodies.step for isotropic inertias (the implicit
 *    midpoint rule on SO(3) x R^3, Rodrigues' formula of zswarm/math/so3.py exp_batch).  Every 3x3
 *    product, here and below, is zswarm/math/so3.py mul's: (a_i0 b_0j + a_i1 b_1j) + a_i2 b_2j, each
 *    operation rounded (no fused multiply-add), and a sum of three squares is (x² + z²) + y², as
 *    so3's numpy code writes them out.  numpy's matmul is not used on either side of this promise:
 *    it goes to the BLAS, whose kernel (chosen at run time by CPU and OPENBLAS_CORETYPE) fuses and
 *    orders the sums its own way.  J_inv must be diagonal (world/dynamics.py checks): then J_inv tau
 *    is exact in any order.
 *  - exp_batch: zswarm/math/so3.py exp_batch, Rodrigues' formula for a stack of rotation vectors.
 *  - flow_xi: agent/algorithms/attitude_sync_terms.py flow_xi, Heun's method on (5.21) in n
 *    sub-steps for each of M draws, with sin and cos of zswarm/math/trig.py (sincos4 below: 4 draws at once).
 *  - sincos: zswarm/math/trig.py sincos.
 *  - flow_aux: the velocity-free law's (Q_i, zeta_i) filter (attitude_sync_velocity_free.py), Heun's
 *    method on SO(3) x R in n sub-steps for each of M draws, four at a time.
 *  - predict, terms: attitude_sync_terms.predict and Terms.
 *  Python's float arithmetic and numpy's elementwise ufuncs round every operation, whatever the CPU; sin and
 *  cos are zswarm/math/trig.py's (sincos4), but for the few that the numpy code takes from the C library through
 *  Python's math module (atan2 and sin in log).  So the same bits hold by construction, on every CPU and BLAS.
 *
 * Built with -ffp-contract=off: the compiler must not fuse a*b + c on its own (that would
 * change the last bit against numpy, which rounds the product and the sum).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

/* The loops come in two builds chosen at load time (GCC's target_clones): with the AVX2 instructions
 * where the CPU has them, and a default one (SSE2: a vector of four is two instructions).  Every
 * operation rounds the same way in both (no fused multiply-add in either), so both give the same bits.  -DZSWARM_DEFAULT_ONLY builds the default one alone (tests/unit/test_kernels.py
 * builds it to compare with the numpy code on a machine that would pick the other). */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && __GNUC__ >= 11 && !defined(ZSWARM_DEFAULT_ONLY)
#define V3_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#define AVX2_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define V3_CLONES
#define AVX2_CLONES
#endif

/* ---- sin and cos of 4 numbers at once (zswarm/math/trig.py does the same operations in Python and numpy).
 * glibc's sin and cos are one call per number (17 ns each on the xi filter's chain, a third of the batched
 * hybrid law's time); these are straight-line IEEE operations on GCC's vector type, which the compiler turns
 * into AVX2 instructions (the avx2 clone) or pairs of SSE2 ones (the default clone): the same operations
 * in the same order, so every lane gives the same bits whatever the lane, the block or the clone, and a
 * draw alone (sim) the same as in a stack of draws (the batched engine).
 * x = n pi/2 + y: n the nearest integer (rounded by adding and subtracting 1.5 2^52), y by Cody and Waite's
 * reduction with pi/2 in four parts (fdlibm's pio2_1, pio2_2, pio2_3 of 33 bits each, the first three
 * products exact for |n| < 2^20, and pio2_3t); sin y and cos y by fdlibm's kernel polynomials on
 * [-pi/4, pi/4] (k_sin.c, k_cos.c, without the tail of y); the quadrant n mod 4 picks and signs them.
 * Measured against sinl/cosl (tests/unit/test_trig.py): at most 1.5 ulp for |x| <= TRIG_LIMIT.  Beyond it
 * (and for inf, NaN) a lane is the C library's sin and cos. */
#define TRIG_LIMIT 16.0
static const double PIO2_1 = 1.57079632673412561417e+00, PIO2_2 = 6.07710050630396597660e-11, PIO2_3 = 2.02226624871116645580e-21,
                    PIO2_3T = 8.47842766036889956997e-32, INVPIO2 = 6.36619772367581382433e-01, RND = 6755399441055744.0;
static const double S1 = -1.66666666666666324348e-01, S2 = 8.33333333332248946124e-03, S3 = -1.98412698298579493134e-04,
                    S4 = 2.75573137070700676789e-06, S5 = -2.50507602534068634195e-08, S6 = 1.58969099521155010221e-10;
static const double C1 = 4.16666666666666019037e-02, C2 = -1.38888888888741095749e-03, C3 = 2.48015872894767294178e-05,
                    C4 = -2.75573143513906633035e-07, C5 = 2.08757232129817482790e-09, C6 = -1.13596475577881948265e-11;

typedef double v4d __attribute__((vector_size(32)));
typedef long long v4i __attribute__((vector_size(32)));

static inline __attribute__((always_inline)) v4d pick(v4i m, v4d a, v4d b) { return (v4d)((m & (v4i)a) | (~m & (v4i)b)); }

static inline __attribute__((always_inline)) void sincos4(v4d x, v4d *so, v4d *co)
{
    const v4d fn = (x * INVPIO2 + RND) - RND;
    const v4d y = (((x - fn * PIO2_1) - fn * PIO2_2) - fn * PIO2_3) - fn * PIO2_3T;
    const v4d f4 = fn * 0.25, r4 = (f4 + RND) - RND;
    const v4d q = fn - 4.0 * pick(r4 > f4, r4 - 1.0, r4); /* n mod 4: 0, 1, 2 or 3 */
    const v4d z = y * y, v = z * y;
    const v4d s = y + v * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))));
    const v4d r = z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))));
    const v4d c = 1.0 - (0.5 * z - z * r);
    const v4i odd = (q == 1.0) | (q == 3.0);
    const v4d ss = pick(odd, c, s), cc = pick(odd, s, c);
    *so = pick(x == 0.0, x, pick(q >= 2.0, -ss, ss)); /* sin(-0) = -0 */
    *co = pick((q == 1.0) | (q == 2.0), -cc, cc);
    const v4i out = ~((x <= TRIG_LIMIT) & (x >= -TRIG_LIMIT));
    if (out[0] | out[1] | out[2] | out[3])
        for (int l = 0; l < 4; l++)
            if (out[l]) {
                (*so)[l] = sin(x[l]);
                (*co)[l] = cos(x[l]);
            }
}

/* sincos4 of one number (lane 0): the same bits. */
static inline __attribute__((always_inline)) void sincos1(double x, double *s, double *c)
{
    const v4d xv = {x, x, x, x};
    v4d sv, cv;
    sincos4(xv, &sv, &cv);
    *s = sv[0];
    *c = cv[0];
}

/* c = a b (3x3, row-major): zswarm/math/so3.py mul's sums, (a_i0 b_0j + a_i1 b_1j) + a_i2 b_2j. */
static inline void mm3(const double *a, const double *b, double *c)
{
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            c[3 * i + k] = (a[3 * i] * b[k] + a[3 * i + 1] * b[3 + k]) + a[3 * i + 2] * b[6 + k];
}

/* Four at a time: lane l of a v4d is draw (or body) l. */
static inline __attribute__((always_inline)) void mm3_4(const v4d *a, const v4d *b, v4d *c)
{
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            c[3 * i + k] = (a[3 * i] * b[k] + a[3 * i + 1] * b[3 + k]) + a[3 * i + 2] * b[6 + k];
}

/* Rodrigues' formula of four rotation vectors (lane l of W[r]: component r of vector l) into E, as
 * zswarm/math/so3.py exp_batch computes it (einsum("ij,ij->i")'s order for |W|²). */
static inline __attribute__((always_inline)) void rodrigues4(const v4d W[3], v4d E[9])
{
    const v4d t2 = (W[0] * W[0] + W[2] * W[2]) + W[1] * W[1];
    v4d s, sn, cs;
    for (int l = 0; l < 4; l++)
        s[l] = sqrt(t2[l]); /* one vsqrtpd (correctly rounded either way) */
    sincos4(s, &sn, &cs);
    const v4i small = t2 < 1e-8;
    const v4d a = pick(small, 1.0 - t2 / 6.0, sn / s), b = pick(small, 0.5 - t2 / 24.0, (1.0 - cs) / t2);
    const v4d z = {0.0, 0.0, 0.0, 0.0};
    const v4d K[9] = {z, -W[2], W[1], W[2], z, -W[0], -W[1], W[0], z};
    v4d KK[9];
    mm3_4(K, K, KK);
    for (int q = 0; q < 9; q++)
        E[q] = ((q % 4 == 0 ? 1.0 : 0.0) + a * K[q]) + b * KK[q];
}

/* zswarm/math/so3.py exp_batch: n rotation vectors W (n,3) -> E (n,3,3), four at a time (the last block
 * padded with its first vector). */
V3_CLONES
void exp_batch(size_t n, const double *W, double *E)
{
    for (size_t m0 = 0; m0 < n; m0 += 4) {
        v4d Wv[3], Ev[9];
        for (int l = 0; l < 4; l++) {
            const size_t m = m0 + l < n ? m0 + l : m0;
            for (int r = 0; r < 3; r++)
                Wv[r][l] = W[3 * m + r];
        }
        rodrigues4(Wv, Ev);
        for (int l = 0; l < 4 && m0 + l < n; l++)
            for (int q = 0; q < 9; q++)
                E[9 * (m0 + l) + q] = Ev[q][l];
    }
}

/* n bodies: R (n,3,3) and w (n,3) advanced by h under the torques tau (n,3) held over the step,
 * into R_out and w_out; J_inv (n,3,3) the inverse inertias (isotropic: J = jI).  Four bodies at a time. */
V3_CLONES
void rigid_step(size_t n, const double *R, const double *w, const double *J_inv, const double *tau, double h, double *R_out, double *w_out)
{
    const double hh = 0.5 * h;
    for (size_t m0 = 0; m0 < n; m0 += 4) {
        v4d Rv[9], J[9], wm[3], t[3], wb[3], W[3], E[9], Rn[9];
        for (int l = 0; l < 4; l++) {
            const size_t m = m0 + l < n ? m0 + l : m0;
            for (int q = 0; q < 9; q++) {
                Rv[q][l] = R[9 * m + q];
                J[q][l] = J_inv[9 * m + q];
            }
            for (int r = 0; r < 3; r++) {
                wm[r][l] = w[3 * m + r];
                t[r][l] = tau[3 * m + r];
            }
        }
        for (int r = 0; r < 3; r++) {
            wb[r] = wm[r] + hh * ((J[3 * r] * t[0] + J[3 * r + 1] * t[1]) + J[3 * r + 2] * t[2]);
            W[r] = h * wb[r];
        }
        rodrigues4(W, E);
        mm3_4(Rv, E, Rn);
        for (int l = 0; l < 4 && m0 + l < n; l++) {
            const size_t m = m0 + l;
            for (int r = 0; r < 3; r++)
                w_out[3 * m + r] = 2.0 * wb[r][l] - wm[r][l];
            for (int q = 0; q < 9; q++)
                R_out[9 * m + q] = Rn[q][l];
        }
    }
}

/* sincos(x, s, c) for n numbers, in 4-lane blocks (the last padded with its first lane). */
AVX2_CLONES
void sincos_n(size_t n, const double *x, double *s, double *c)
{
    for (size_t i0 = 0; i0 < n; i0 += 4) {
        v4d xv, sv, cv;
        for (int l = 0; l < 4; l++)
            xv[l] = x[i0 + l < n ? i0 + l : i0];
        sincos4(xv, &sv, &cv);
        for (int l = 0; l < 4 && i0 + l < n; l++) {
            s[i0 + l] = sv[l];
            c[i0 + l] = cv[l];
        }
    }
}

/* M draws of xi advanced in place by dt in n Heun sub-steps of
 * xi' = -k_xi (gamma xi + 2 (a + b sin xi + q (1 - cos xi))), (a, b, q) going linearly from
 * (a0, b0, q0) to (a1, b1, q1) over the interval; sin and cos by sincos4.  The draws go in blocks of
 * 4 K lanes (K chains side by side hide the polynomials' latency), K = 4 while 16 draws are left, then 1;
 * a lane's numbers do not depend on its block. */
#define XI_BLOCK(K)                                                                                                                 \
    do {                                                                                                                            \
        v4d xi[K], a0[K], b0[K], q0[K], da[K], db[K], dq[K], f[K], x1[K], s[K], c[K];                                              \
        for (int k = 0; k < K; k++) {                                                                                               \
            v4d a1, b1, q1;                                                                                                         \
            for (int l = 0; l < 4; l++) {                                                                                           \
                const size_t i = i0 + 4 * k + l < M ? i0 + 4 * k + l : i0;                                                         \
                xi[k][l] = xv[i], a0[k][l] = a0v[i], b0[k][l] = b0v[i], q0[k][l] = q0v[i], a1[l] = a1v[i], b1[l] = b1v[i], q1[l] = q1v[i]; \
            }                                                                                                                       \
            da[k] = a1 - a0[k], db[k] = b1 - b0[k], dq[k] = q1 - q0[k];                                                             \
            sincos4(xi[k], &s[k], &c[k]);                                                                                           \
            f[k] = -kg * xi[k] - two_k * ((a0[k] + b0[k] * s[k]) + q0[k] * (1.0 - c[k]));                                           \
        }                                                                                                                           \
        for (long m = 0; m < n; m++) {                                                                                              \
            const double s1 = (double)(m + 1) / (double)n;                                                                          \
            for (int k = 0; k < K; k++) {                                                                                           \
                x1[k] = xi[k] + h * f[k];                                                                                           \
                sincos4(x1[k], &s[k], &c[k]);                                                                                       \
            }                                                                                                                       \
            for (int k = 0; k < K; k++) {                                                                                           \
                const v4d a1 = a0[k] + s1 * da[k], b1 = b0[k] + s1 * db[k], q1 = q0[k] + s1 * dq[k];                                \
                xi[k] = xi[k] + 0.5 * h * (f[k] + (-kg * x1[k] - two_k * ((a1 + b1 * s[k]) + q1 * (1.0 - c[k]))));                 \
            }                                                                                                                       \
            if (m + 1 == n)                                                                                                         \
                break; /* the rate at the end of the last sub-step is not needed */                                                 \
            for (int k = 0; k < K; k++) {                                                                                           \
                const v4d a1 = a0[k] + s1 * da[k], b1 = b0[k] + s1 * db[k], q1 = q0[k] + s1 * dq[k];                                \
                sincos4(xi[k], &s[k], &c[k]);                                                                                       \
                f[k] = -kg * xi[k] - two_k * ((a1 + b1 * s[k]) + q1 * (1.0 - c[k]));                                                \
            }                                                                                                                       \
        }                                                                                                                           \
        for (int k = 0; k < K; k++)                                                                                                 \
            for (int l = 0; l < 4 && i0 + 4 * k + l < M; l++)                                                                       \
                xv[i0 + 4 * k + l] = xi[k][l];                                                                                      \
        i0 += 4 * K;                                                                                                                \
    } while (0)

AVX2_CLONES
void flow_xi(size_t M, const double *a0v, const double *b0v, const double *q0v, const double *a1v, const double *b1v, const double *q1v,
             double *xv, double dt, double k_xi, double gamma, long n)
{
    const double h = dt / (double)n, two_k = 2.0 * k_xi, kg = k_xi * gamma;
    size_t i0 = 0;
    while (M - i0 >= 16)
        XI_BLOCK(4);
    while (i0 < M)
        XI_BLOCK(1);
}

/* flow_xi of one draw (sim's path, one agent and edge at a time). */
double flow_xi_one(double a0, double b0, double q0, double a1, double b1, double q1, double xi, double dt, double k_xi, double gamma, long n)
{
    flow_xi(1, &a0, &b0, &q0, &a1, &b1, &q1, &xi, dt, k_xi, gamma, n);
    return xi;
}

/* ---- attitude_sync_terms: the prediction of R̄ and the Terms of the potential (4.23), as their numpy code
 * computes them on a stack of draws (one draw goes the same way as a stack of one). */

/* zswarm/math/so3.py log_batch of one matrix: its rotation vector into w, 1; 0 when theta >= pi - 1e-4 (so3.log's
 * branch near pi: the caller does it). */
static inline int log_mid(const double D[9], double w[3])
{
    const double c = (((D[0] + D[4]) + D[8]) - 1.0) * 0.5;
    const double s[3] = {(D[7] - D[5]) * 0.5, (D[2] - D[6]) * 0.5, (D[3] - D[1]) * 0.5};
    const double theta = atan2(sqrt((s[0] * s[0] + s[2] * s[2]) + s[1] * s[1]), c);
    double f;
    if (theta < 1e-6)
        f = 1.0 + theta * theta / 6.0;
    else if (theta < M_PI - 1e-4)
        f = theta / sin(theta);
    else
        return 0;
    for (int r = 0; r < 3; r++)
        w[r] = s[r] * f;
    return 1;
}

/* zswarm/math/so3.py log_batch of M matrices R (M,3,3) into w (M,3); a matrix near pi is left as NaN (the caller does
 * it).  Returns how many were. */
long log_stack(size_t M, const double *R, double *w)
{
    long left = 0;
    for (size_t m = 0; m < M; m++)
        if (!log_mid(R + 9 * m, w + 3 * m)) {
            w[3 * m] = w[3 * m + 1] = w[3 * m + 2] = NAN;
            left++;
        }
    return left;
}

/* attitude_sync_terms.predict for M draws: out = R_now exp(ratio log(R_prev^T R_now)); a draw whose
 * log is near pi is left as NaN (the caller computes it).  Returns how many were.  Four draws at a time:
 * the products and Rodrigues' formula on the vector type, the log's atan2 and sin a lane at a time. */
V3_CLONES
long predict(size_t M, const double *Rp, const double *Rn, double ratio, double *out)
{
    long left = 0;
    for (size_t m0 = 0; m0 < M; m0 += 4) {
        v4d P[9], N[9], D[9], W[3], E[9], O[9];
        int ok[4];
        for (int l = 0; l < 4; l++) {
            const size_t m = m0 + l < M ? m0 + l : m0;
            for (int q = 0; q < 9; q++) {
                P[q][l] = Rp[9 * m + q];
                N[q][l] = Rn[9 * m + q];
            }
        }
        for (int i = 0; i < 3; i++) /* R_prev^T R_now, so3.mul(T(R_prev), R_now): the same sums over the inner index */
            for (int k = 0; k < 3; k++)
                D[3 * i + k] = (P[i] * N[k] + P[3 + i] * N[3 + k]) + P[6 + i] * N[6 + k];
        for (int l = 0; l < 4; l++) {
            double Dl[9], w[3];
            for (int q = 0; q < 9; q++)
                Dl[q] = D[q][l];
            ok[l] = log_mid(Dl, w);
            for (int r = 0; r < 3; r++)
                W[r][l] = ok[l] ? w[r] : 0.0;
        }
        for (int r = 0; r < 3; r++)
            W[r] = ratio * W[r];
        rodrigues4(W, E);
        mm3_4(N, E, O);
        for (int l = 0; l < 4 && m0 + l < M; l++) {
            for (int q = 0; q < 9; q++)
                out[9 * (m0 + l) + q] = ok[l] ? O[q][l] : NAN;
            left += !ok[l];
        }
    }
    return left;
}

/* attitude_sync_terms.Terms for M draws of R̄ (M,3,3): with X = A R̄, XK = X K, XK2 = XK K, the column
 * (psi(X), psi(XK), psi(XK2), tr X, tr XK, tr XK2, u.psi(X), u.psi(XK), u.psi(XK2)) of out (15,M): each
 * quantity a row of M, contiguous for the numpy and the flow_xi that read it. */
void terms(size_t M, const double *A, const double *K, const double *u, const double *R, double *out)
{
    for (size_t m = 0; m < M; m++) {
        double X[3][9];
        mm3(A, R + 9 * m, X[0]);
        mm3(X[0], K, X[1]);
        mm3(X[1], K, X[2]);
        for (int j = 0; j < 3; j++) {
            const double *Y = X[j];
            const double p0 = (Y[7] - Y[5]) * 0.5, p1 = (Y[2] - Y[6]) * 0.5, p2 = (Y[3] - Y[1]) * 0.5;
            out[(3 * j) * M + m] = p0, out[(3 * j + 1) * M + m] = p1, out[(3 * j + 2) * M + m] = p2;
            out[(9 + j) * M + m] = (Y[0] + Y[4]) + Y[8];
            out[(12 + j) * M + m] = (p0 * u[0] + p1 * u[1]) + p2 * u[2]; /* so3.dot's order */
        }
    }
}

/* (k_Q h_i, zeta') of attitude_sync_velocity_free _Rates for four draws: Z = Ra(zeta, u) from K = [u]^x and
 * K2 = K K (sin and cos by sincos4), p = psi((A Qt) Z), k_Q Z p and -k_zeta (gamma zeta + p . 2u), the products
 * Z p and p . 2u summed (x0 y0 + x1 y1) + x2 y2. */
static inline __attribute__((always_inline)) void aux_rates4(const v4d Qt[9], v4d z, const v4d A[9], const double K[9], const double K2[9],
                                                             const double u2[3], double k_Q, double nk_zeta, double gamma, v4d kh[3], v4d *zd)
{
    v4d s, c, Z[9], X[9], Y[9];
    sincos4(z, &s, &c);
    c = 1.0 - c;
    for (int q = 0; q < 9; q++)
        Z[q] = ((q % 4 == 0 ? 1.0 : 0.0) + s * K[q]) + c * K2[q];
    mm3_4(A, Qt, X);
    mm3_4(X, Z, Y);
    const v4d p0 = (Y[7] - Y[5]) * 0.5, p1 = (Y[2] - Y[6]) * 0.5, p2 = (Y[3] - Y[1]) * 0.5;
    for (int r = 0; r < 3; r++)
        kh[r] = k_Q * ((Z[3 * r] * p0 + Z[3 * r + 1] * p1) + Z[3 * r + 2] * p2);
    *zd = nk_zeta * (gamma * z + ((p0 * u2[0] + p1 * u2[1]) + p2 * u2[2]));
}

/* agent/algorithms/attitude_sync_velocity_free.py flow_aux's sub-steps for M draws: Heun's method on
 * (Qt, zeta) (thesis (5.14), (5.23)), Qt (M,3,3) and zeta (M) advanced in place by n sub-steps of h;
 * sub-step m reads the body rate table[rows[m]] (table (rows, M, 3)).  Four draws at a time (the last
 * block padded with its first draw); the rates after the last sub-step, which nothing reads, are not
 * computed. */
V3_CLONES
void flow_aux(size_t M, long n, double *Qt_all, double *z_all, const double *table, const int64_t *rows, double h, const double *A, const double *K,
              const double *K2, const double *u2, double k_Q, double k_zeta, double gamma)
{
    const double hh = 0.5 * h, nk = -k_zeta;
    v4d Av[9];
    for (int q = 0; q < 9; q++)
        Av[q] = (v4d){A[q], A[q], A[q], A[q]};
    for (size_t m0 = 0; m0 < M; m0 += 4) {
        size_t lane[4];
        v4d Qt[9], z, z1, z2, kh1[3], kh2[3], w[3], v1[3], W[3], E[9], Q1[9];
        for (int l = 0; l < 4; l++) {
            lane[l] = m0 + l < M ? m0 + l : m0;
            for (int q = 0; q < 9; q++)
                Qt[q][l] = Qt_all[9 * lane[l] + q];
            z[l] = z_all[lane[l]];
        }
        aux_rates4(Qt, z, Av, K, K2, u2, k_Q, nk, gamma, kh1, &z1);
        for (long k = 0; k < n; k++) {
            for (int l = 0; l < 4; l++)
                for (int r = 0; r < 3; r++)
                    w[r][l] = table[3 * ((size_t)rows[k] * M + lane[l]) + r];
            for (int r = 0; r < 3; r++) {
                v1[r] = w[r] - kh1[r];
                W[r] = h * v1[r];
            }
            rodrigues4(W, E);
            mm3_4(Qt, E, Q1);
            aux_rates4(Q1, z + h * z1, Av, K, K2, u2, k_Q, nk, gamma, kh2, &z2);
            for (int r = 0; r < 3; r++)
                W[r] = hh * ((v1[r] + w[r]) - kh2[r]);
            rodrigues4(W, E);
            mm3_4(Qt, E, Q1);
            for (int q = 0; q < 9; q++)
                Qt[q] = Q1[q];
            z = z + hh * (z1 + z2);
            if (k + 1 < n)
                aux_rates4(Qt, z, Av, K, K2, u2, k_Q, nk, gamma, kh1, &z1);
        }
        for (int l = 0; l < 4 && m0 + l < M; l++) {
            for (int q = 0; q < 9; q++)
                Qt_all[9 * (m0 + l) + q] = Qt[q][l];
            z_all[m0 + l] = z[l];
        }
    }
}

/* ---- The module's functions: METH_FASTCALL, arrays by the buffer protocol (C-contiguous, 8-byte items of
 * the right kind, the exact number of bytes each needs), numbers as Python floats and ints.  A call costs
 * ~0.1 us per argument where ctypes took 2-4 us per array (numpy's .ctypes objects): per call of a single
 * draw (sim's agents and the world's 1 kHz rigid-body step) that was most of the time. */

enum { F64 = 'd', I64 = 'q' };

/* A buffer of `kind` items from o into b: its item count, or -1 with an exception set. */
static Py_ssize_t get_buf(PyObject *o, Py_buffer *b, int kind, int writable, const char *name)
{
    if (PyObject_GetBuffer(o, b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0)
        return -1;
    const char *f = b->format ? b->format : "B";
    if (*f == '<' || *f == '=' || *f == '@')
        f++;
    const int ok = b->itemsize == 8 && f[1] == '\0' && (kind == F64 ? f[0] == 'd' : (f[0] == 'q' || f[0] == 'l'));
    if (!ok) {
        PyErr_Format(PyExc_TypeError, "%s: an array of %s expected", name, kind == F64 ? "float64" : "int64");
        PyBuffer_Release(b);
        return -1;
    }
    return b->len / 8;
}

static int want_items(Py_buffer *b, Py_ssize_t n, const char *name)
{
    if (b->len / 8 == n)
        return 0;
    PyErr_Format(PyExc_ValueError, "%s: %zd values, %zd needed", name, b->len / 8, n);
    return -1;
}

static int want_nargs(Py_ssize_t nargs, Py_ssize_t n, const char *fn)
{
    if (nargs == n)
        return 0;
    PyErr_Format(PyExc_TypeError, "%s: %zd arguments, %zd given", fn, n, nargs);
    return -1;
}

#define MAXBUF 12
typedef struct {
    Py_buffer b[MAXBUF];
    int n;
} Bufs;

static void release_all(Bufs *B)
{
    for (int i = 0; i < B->n; i++)
        PyBuffer_Release(&B->b[i]);
    B->n = 0;
}

/* The next buffer of B from o: its item count, or -1. */
static Py_ssize_t take(Bufs *B, PyObject *o, int kind, int writable, const char *name)
{
    const Py_ssize_t n = get_buf(o, &B->b[B->n], kind, writable, name);
    if (n >= 0)
        B->n++;
    return n;
}

#define D(i) ((double *)B.b[i].buf)

/* exp_batch(W (n,3), E (n,3,3) out) */
static PyObject *py_exp_batch(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    Bufs B = {.n = 0};
    if (want_nargs(nargs, 2, "exp_batch") < 0)
        return NULL;
    const Py_ssize_t nw = take(&B, a[0], F64, 0, "W");
    if (nw < 0)
        return NULL;
    if (nw % 3) {
        PyErr_SetString(PyExc_ValueError, "W: a stack of 3-vectors expected");
        release_all(&B);
        return NULL;
    }
    if (take(&B, a[1], F64, 1, "E") < 0 || want_items(&B.b[1], 3 * nw, "E") < 0) {
        release_all(&B);
        return NULL;
    }
    exp_batch((size_t)(nw / 3), D(0), D(1));
    release_all(&B);
    Py_RETURN_NONE;
}

/* rigid_step(R (n,3,3), w (n,3), J_inv (n,3,3), tau (n,3), h, R_out (n,3,3) out, w_out (n,3) out) */
static PyObject *py_rigid_step(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    Bufs B = {.n = 0};
    if (want_nargs(nargs, 7, "rigid_step") < 0)
        return NULL;
    const double h = PyFloat_AsDouble(a[4]);
    if (h == -1.0 && PyErr_Occurred())
        return NULL;
    const Py_ssize_t nw = take(&B, a[1], F64, 0, "w");
    if (nw < 0 || nw % 3) {
        if (nw >= 0)
            PyErr_SetString(PyExc_ValueError, "w: a stack of 3-vectors expected");
        release_all(&B);
        return NULL;
    }
    const Py_ssize_t n = nw / 3;
    if (take(&B, a[0], F64, 0, "R") < 0 || want_items(&B.b[1], 9 * n, "R") < 0 || take(&B, a[2], F64, 0, "J_inv") < 0 || want_items(&B.b[2], 9 * n, "J_inv") < 0 ||
        take(&B, a[3], F64, 0, "tau") < 0 || want_items(&B.b[3], 3 * n, "tau") < 0 || take(&B, a[5], F64, 1, "R_out") < 0 || want_items(&B.b[4], 9 * n, "R_out") < 0 ||
        take(&B, a[6], F64, 1, "w_out") < 0 || want_items(&B.b[5], 3 * n, "w_out") < 0) {
        release_all(&B);
        return NULL;
    }
    rigid_step((size_t)n, D(1), D(0), D(2), D(3), h, D(4), D(5));
    release_all(&B);
    Py_RETURN_NONE;
}

/* Numbers a[first .. first + count - 1] into out; -1 with an exception set. */
static int doubles(PyObject *const *a, int first, int count, double *out)
{
    for (int i = 0; i < count; i++) {
        out[i] = PyFloat_AsDouble(a[first + i]);
        if (out[i] == -1.0 && PyErr_Occurred())
            return -1;
    }
    return 0;
}

static int positive_long(PyObject *o, long *out, const char *name)
{
    *out = PyLong_AsLong(o);
    if (*out == -1 && PyErr_Occurred())
        return -1;
    if (*out < 0) {
        PyErr_Format(PyExc_ValueError, "%s: must be >= 0", name);
        return -1;
    }
    return 0;
}

/* flow_xi_one(a0, b0, q0, a1, b1, q1, xi, dt, k_xi, gamma, n) -> xi after dt */
static PyObject *py_flow_xi_one(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    double v[10];
    long n;
    if (want_nargs(nargs, 11, "flow_xi_one") < 0 || doubles(a, 0, 10, v) < 0 || positive_long(a[10], &n, "n") < 0)
        return NULL;
    return PyFloat_FromDouble(flow_xi_one(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], n));
}

/* The buffers released and NULL returned, the exception set: the one raised, or that `name` (n values)
 * is not a stack of 3x3 matrices. */
static PyObject *fail_stack(Bufs *B, Py_ssize_t n, const char *name)
{
    if (!PyErr_Occurred())
        PyErr_Format(PyExc_ValueError, "%s: not a stack of 3x3 matrices (%zd values)", name, n);
    release_all(B);
    return NULL;
}

/* predict(R_prev (M,3,3), R_now (M,3,3), ratio, out (M,3,3) out) -> draws left (near pi) */
static PyObject *py_predict(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    Bufs B = {.n = 0};
    double ratio;
    if (want_nargs(nargs, 4, "predict") < 0 || doubles(a, 2, 1, &ratio) < 0)
        return NULL;
    const Py_ssize_t n = take(&B, a[1], F64, 0, "R_now");
    if (n < 0 || n % 9 || take(&B, a[0], F64, 0, "R_prev") < 0 || want_items(&B.b[1], n, "R_prev") < 0 || take(&B, a[3], F64, 1, "out") < 0 ||
        want_items(&B.b[2], n, "out") < 0)
        return fail_stack(&B, n, "R_now");
    const long left = predict((size_t)(n / 9), D(1), D(0), ratio, D(2));
    release_all(&B);
    return PyLong_FromLong(left);
}

/* log_stack(R (M,3,3), w (M,3) out) -> matrices left (near pi) */
static PyObject *py_log_stack(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    Bufs B = {.n = 0};
    if (want_nargs(nargs, 2, "log_stack") < 0)
        return NULL;
    const Py_ssize_t n = take(&B, a[0], F64, 0, "R");
    if (n < 0 || n % 9 || take(&B, a[1], F64, 1, "w") < 0 || want_items(&B.b[1], n / 3, "w") < 0)
        return fail_stack(&B, n, "R");
    const long left = log_stack((size_t)(n / 9), D(0), D(1));
    release_all(&B);
    return PyLong_FromLong(left);
}

/* terms(A (3,3), K (3,3), u (3), R (M,3,3), out (15,M) out) */
static PyObject *py_terms(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    Bufs B = {.n = 0};
    if (want_nargs(nargs, 5, "terms") < 0)
        return NULL;
    Py_ssize_t n = -1;
    if (take(&B, a[0], F64, 0, "A") < 0 || want_items(&B.b[0], 9, "A") < 0 || take(&B, a[1], F64, 0, "K") < 0 || want_items(&B.b[1], 9, "K") < 0 ||
        take(&B, a[2], F64, 0, "u") < 0 || want_items(&B.b[2], 3, "u") < 0 || (n = take(&B, a[3], F64, 0, "R")) < 0 || n % 9 ||
        take(&B, a[4], F64, 1, "out") < 0 || want_items(&B.b[4], n / 9 * 15, "out") < 0)
        return fail_stack(&B, n, "R");
    terms((size_t)(n / 9), D(0), D(1), D(2), D(3), D(4));
    release_all(&B);
    Py_RETURN_NONE;
}

/* sincos1(x) -> (sin x, cos x): sincos of one number (zswarm/math/trig.py sincos of a float). */
static PyObject *py_sincos1(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    double x, s, c;
    if (want_nargs(nargs, 1, "sincos1") < 0 || doubles(a, 0, 1, &x) < 0)
        return NULL;
    sincos1(x, &s, &c);
    return Py_BuildValue("(dd)", s, c);
}

/* sincos(x (n), s (n) out, c (n) out) */
static PyObject *py_sincos(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    Bufs B = {.n = 0};
    if (want_nargs(nargs, 3, "sincos") < 0)
        return NULL;
    const Py_ssize_t n = take(&B, a[0], F64, 0, "x");
    if (n < 0 || take(&B, a[1], F64, 1, "s") < 0 || want_items(&B.b[1], n, "s") < 0 || take(&B, a[2], F64, 1, "c") < 0 || want_items(&B.b[2], n, "c") < 0) {
        release_all(&B);
        return NULL;
    }
    sincos_n((size_t)n, D(0), D(1), D(2));
    release_all(&B);
    Py_RETURN_NONE;
}

/* flow_xi(a0, b0, q0, a1, b1, q1 (M) each, x (M) in/out, dt, k_xi, gamma, n) */
static PyObject *py_flow_xi(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    Bufs B = {.n = 0};
    double v[3];
    long n;
    if (want_nargs(nargs, 11, "flow_xi") < 0 || doubles(a, 7, 3, v) < 0 || positive_long(a[10], &n, "n") < 0)
        return NULL;
    const Py_ssize_t M = take(&B, a[6], F64, 1, "x");
    if (M < 0)
        return NULL;
    static const char *names[6] = {"a0", "b0", "q0", "a1", "b1", "q1"};
    for (int i = 0; i < 6; i++)
        if (take(&B, a[i], F64, 0, names[i]) < 0 || want_items(&B.b[B.n - 1], M, names[i]) < 0) {
            release_all(&B);
            return NULL;
        }
    flow_xi((size_t)M, D(1), D(2), D(3), D(4), D(5), D(6), D(0), v[0], v[1], v[2], n);
    release_all(&B);
    Py_RETURN_NONE;
}

/* flow_aux(Qt (M,3,3) in/out, zeta (M) in/out, table (rows,M,3), rows (n) int64, h, A, K, K2 (3,3) each,
 * u2 (3), k_Q, k_zeta, gamma) */
static PyObject *py_flow_aux(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    Bufs B = {.n = 0};
    double v[4];
    if (want_nargs(nargs, 12, "flow_aux") < 0 || doubles(a, 4, 1, v) < 0 || doubles(a, 9, 3, v + 1) < 0)
        return NULL;
    const Py_ssize_t M = take(&B, a[1], F64, 1, "zeta");
    if (M < 0)
        return NULL;
    Py_ssize_t nt = 0, nr = 0;
    if (take(&B, a[0], F64, 1, "Qt") < 0 || want_items(&B.b[1], 9 * M, "Qt") < 0 || (nt = take(&B, a[2], F64, 0, "table")) < 0 ||
        (nr = take(&B, a[3], I64, 0, "rows")) < 0 || take(&B, a[5], F64, 0, "A") < 0 || want_items(&B.b[4], 9, "A") < 0 ||
        take(&B, a[6], F64, 0, "K") < 0 || want_items(&B.b[5], 9, "K") < 0 || take(&B, a[7], F64, 0, "K2") < 0 || want_items(&B.b[6], 9, "K2") < 0 ||
        take(&B, a[8], F64, 0, "u2") < 0 || want_items(&B.b[7], 3, "u2") < 0) {
        release_all(&B);
        return NULL;
    }
    if (M > 0 && nt % (3 * M)) {
        PyErr_SetString(PyExc_ValueError, "table: (rows, M, 3) expected");
        release_all(&B);
        return NULL;
    }
    const Py_ssize_t table_rows = M > 0 ? nt / (3 * M) : 0;
    const int64_t *rows = (const int64_t *)B.b[3].buf;
    for (Py_ssize_t k = 0; M > 0 && k < nr; k++)
        if (rows[k] < 0 || rows[k] >= table_rows) {
            PyErr_SetString(PyExc_IndexError, "flow_aux: a sub-step's row is outside the rate table");
            release_all(&B);
            return NULL;
        }
    flow_aux((size_t)M, (long)nr, D(1), D(0), D(2), rows, v[0], D(4), D(5), D(6), D(7), v[1], v[2], v[3]);
    release_all(&B);
    Py_RETURN_NONE;
}

/* ---- The wire's checks of a decoded message (zswarm/transport/message_checks.py), for the arrays a
 * decoded payload holds: exact numpy arrays (the type given to set_ndarray), read-only, C-contiguous
 * float64 of the shape.  The verdict of each is the Python's: every number finite and within
 * +-max_abs (comparisons that NaN fails), a unit vector's | (x x + y y) + z z - 1 | <= 2 tol and a
 * rotation's sums as so3._rotation_ok writes them, each operation in the same order and rounded
 * (-ffp-contract=off).  True or False only: on False the Python runs and names the problem; an
 * array of any other kind (a sender's, writable; a list) is False here and checked there. */
static PyObject *ndarray_type = NULL;

enum { CHECK_NONE = 0, CHECK_UNIT = 1, CHECK_ROTATION = 2 };

/* 1: o is an exact numpy array (the type given to set_ndarray) of native float64 values, its buffer
 * (PyBUF_RECORDS_RO: shape and strides) in b, which the caller releases; 0: not, nothing held. */
static int f8_buffer(PyObject *o, Py_buffer *b)
{
    if (ndarray_type == NULL || (PyObject *)Py_TYPE(o) != ndarray_type)
        return 0;
    if (PyObject_GetBuffer(o, b, PyBUF_RECORDS_RO) < 0) {
        PyErr_Clear();
        return 0;
    }
    const char *f = b->format ? b->format : "B";
    if (*f == '<' || *f == '=' || *f == '@')
        f++;
    if (b->itemsize == 8 && f[0] == 'd' && f[1] == '\0')
        return 1;
    PyBuffer_Release(b);
    return 0;
}

/* 1: o is a decoded float64 array of n (3 or 9) values, shape (3,) or (3, 3), all within +-max_abs
 * and passing `check`; 0: not (or not such an array); -1: an error. */
static int f8_check(PyObject *o, int n, int check, double max_abs, double tol)
{
    Py_buffer b;
    if (!f8_buffer(o, &b))
        return 0;
    int ok = b.readonly && b.len == 8 * n && PyBuffer_IsContiguous(&b, 'C') &&
             (n == 3 ? b.ndim == 1 && b.shape[0] == 3 : b.ndim == 2 && b.shape[0] == 3 && b.shape[1] == 3);
    if (ok) {
        const double *x = (const double *)b.buf;
        for (int k = 0; k < n; k++)
            if (!(fabs(x[k]) <= max_abs))
                ok = 0;
        if (ok && check == CHECK_UNIT && n == 3)
            ok = fabs(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] - 1.0) <= 2 * tol;
        else if (ok && check == CHECK_ROTATION && n == 9) {
            const double a = x[0], bb = x[1], c = x[2], d = x[3], e = x[4], ff = x[5], g = x[6], h = x[7], i = x[8];
            ok = fabs(a * a + d * d + g * g - 1.0) <= tol && fabs(bb * bb + e * e + h * h - 1.0) <= tol && fabs(c * c + ff * ff + i * i - 1.0) <= tol &&
                 fabs(a * bb + d * e + g * h) <= tol && fabs(a * c + d * ff + g * i) <= tol && fabs(bb * c + e * ff + h * i) <= tol &&
                 fabs(a * (e * i - ff * h) - bb * (d * i - ff * g) + c * (d * h - e * g) - 1.0) <= tol;
        } else if (ok && check != CHECK_NONE)
            ok = 0;
    }
    PyBuffer_Release(&b);
    return ok;
}

static int parse_check_args(PyObject *const *a, int *n, int *check, double *max_abs, double *tol)
{
    *n = (int)PyLong_AsLong(a[1]);
    *check = (int)PyLong_AsLong(a[2]);
    *max_abs = PyFloat_AsDouble(a[3]);
    *tol = PyFloat_AsDouble(a[4]);
    if (PyErr_Occurred())
        return -1;
    if (*n != 3 && *n != 9) {
        PyErr_SetString(PyExc_ValueError, "n: 3 or 9");
        return -1;
    }
    return 0;
}

/* f8_ok(a, n, check, max_abs, tol) -> bool */
static PyObject *py_f8_ok(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    int n, check;
    double max_abs, tol;
    if (want_nargs(nargs, 5, "f8_ok") < 0 || parse_check_args(a, &n, &check, &max_abs, &tol) < 0)
        return NULL;
    const int r = f8_check(a[0], n, check, max_abs, tol);
    if (r < 0)
        return NULL;
    return PyBool_FromLong(r);
}

/* idmap_ok(d, n, check, max_abs, tol, max_id, max_ids) -> bool: d an exact dict of at most max_ids
 * entries, each key an exact int in [0, max_id], each value f8_check's. */
static PyObject *py_idmap_ok(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    int n, check;
    double max_abs, tol;
    if (want_nargs(nargs, 7, "idmap_ok") < 0 || parse_check_args(a, &n, &check, &max_abs, &tol) < 0)
        return NULL;
    const long long max_id = PyLong_AsLongLong(a[5]);
    const Py_ssize_t max_ids = PyLong_AsSsize_t(a[6]);
    if (PyErr_Occurred())
        return NULL;
    PyObject *d = a[0];
    if (!PyDict_CheckExact(d) || PyDict_GET_SIZE(d) > max_ids)
        Py_RETURN_FALSE;
    Py_ssize_t pos = 0;
    PyObject *k, *v;
    while (PyDict_Next(d, &pos, &k, &v)) {
        if (!PyLong_CheckExact(k))
            Py_RETURN_FALSE;
        int overflow = 0;
        const long long j = PyLong_AsLongLongAndOverflow(k, &overflow);
        if (overflow || j < 0 || j > max_id)
            Py_RETURN_FALSE;
        const int r = f8_check(v, n, check, max_abs, tol);
        if (r < 0)
            return NULL;
        if (!r)
            Py_RETURN_FALSE;
    }
    Py_RETURN_TRUE;
}

/* set_ndarray(numpy.ndarray): the one type of array the checks above accept. */
static PyObject *py_set_ndarray(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    if (want_nargs(nargs, 1, "set_ndarray") < 0)
        return NULL;
    if (!PyType_Check(a[0])) {
        PyErr_SetString(PyExc_TypeError, "set_ndarray: a type expected");
        return NULL;
    }
    Py_XDECREF(ndarray_type);
    Py_INCREF(a[0]);
    ndarray_type = a[0];
    Py_RETURN_NONE;
}

/* 1: o is a float64 array of shape (3,) (n = 3) or (3, 3) (n = 9), any strides, copied into x (row-major); 0: not. */
static int read_f8(PyObject *o, int n, double *x)
{
    Py_buffer b;
    if (!f8_buffer(o, &b))
        return 0;
    int ok = (n == 3 ? b.ndim == 1 && b.shape[0] == 3 : b.ndim == 2 && b.shape[0] == 3 && b.shape[1] == 3);
    if (ok) {
        const char *base = (const char *)b.buf;
        if (n == 3)
            for (int i = 0; i < 3; i++)
                memcpy(x + i, base + i * b.strides[0], 8);
        else
            for (int i = 0; i < 3; i++)
                for (int k = 0; k < 3; k++)
                    memcpy(x + 3 * i + k, base + i * b.strides[0] + k * b.strides[1], 8);
    }
    PyBuffer_Release(&b);
    return ok;
}

/* n values into the writable float64 array o of exactly n; -1 with an exception set. */
static int write_f8(PyObject *o, int n, const double *x)
{
    Bufs B = {.n = 0};
    if (take(&B, o, F64, 1, "out") < 0 || want_items(&B.b[0], n, "out") < 0) {
        release_all(&B);
        return -1;
    }
    memcpy(B.b[0].buf, x, 8 * (size_t)n);
    release_all(&B);
    return 0;
}

/* ---- the gyro's pre-integration on one agent (zswarm/math/timing.py _integrate, a single rate
 * vector per sample): the same operations in the same order as the Python, so the same bits.  The
 * Python did it in ~20 us a step (a tenth of a §3.2 agent's tick, 2026-12-06); here ~1 us. */

#define RATE_MAX 256 /* samples read at most (an agent keeps 64; more go to the Python) */

/* The sample times' insertion point after x (Python's bisect.bisect_right on ts[0..n)). */
static Py_ssize_t bisect_right(const double *ts, Py_ssize_t n, double x)
{
    Py_ssize_t lo = 0, hi = n;
    while (lo < hi) {
        const Py_ssize_t mid = (lo + hi) / 2;
        if (x < ts[mid])
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

static inline double py_max(double a, double b) { return b > a ? b : a; } /* Python's max(a, b) */
static inline double py_min(double a, double b) { return b < a ? b : a; } /* Python's min(a, b) */

/* rate_integral(samples, t0, t1, magnus, out (3) out) -> bool: timing._integrate of samples, a list
 * of at least 2 (time, float64 (3,) array) tuples, for t0 < t1, into out; False (out untouched): the
 * samples are not such (a stack of draws, another type), for the Python to do. */
static PyObject *py_rate_integral(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    double tt[2];
    if (want_nargs(nargs, 5, "rate_integral") < 0 || doubles(a, 1, 2, tt) < 0)
        return NULL;
    const double t0 = tt[0], t1 = tt[1];
    const int magnus = PyObject_IsTrue(a[3]);
    if (magnus < 0)
        return NULL;
    PyObject *samples = a[0];
    if (!PyList_CheckExact(samples))
        Py_RETURN_FALSE;
    const Py_ssize_t n = PyList_GET_SIZE(samples);
    if (n < 2 || n > RATE_MAX || !(t0 < t1))
        Py_RETURN_FALSE;
    double ts_all[RATE_MAX];
    for (Py_ssize_t k = 0; k < n; k++) {
        PyObject *s = PyList_GET_ITEM(samples, k);
        if (!PyTuple_CheckExact(s) || PyTuple_GET_SIZE(s) != 2 || !PyFloat_CheckExact(PyTuple_GET_ITEM(s, 0)))
            Py_RETURN_FALSE;
        ts_all[k] = PyFloat_AS_DOUBLE(PyTuple_GET_ITEM(s, 0));
    }
    Py_ssize_t first = bisect_right(ts_all, n, t0) - 1;
    if (first > n - 2)
        first = n - 2;
    if (first < 0)
        first = 0;
    const Py_ssize_t m = n - first; /* ts = ts_all[first:], W its rates */
    const double *ts = ts_all + first;
    double W[RATE_MAX][3];
    for (Py_ssize_t k = 0; k < m; k++)
        if (!read_f8(PyTuple_GET_ITEM(PyList_GET_ITEM(samples, first + k), 1), 3, W[k]))
            Py_RETURN_FALSE;
    const double gap = ts_all[n - 1] - ts_all[n - 2];
    const double *Wl = W[m - 1], *Wp = W[m - 2];
    double slope[3];
    for (int c = 0; c < 3; c++)
        slope[c] = gap > 0 ? (Wl[c] - Wp[c]) / gap : 0.0 * Wl[c];
    const double t_last = ts_all[n - 1];
    const double t_cap = t_last + py_max(gap, 0.0);
    /* The grid: t0, t1 and the sample times and t_cap strictly between them, sorted, each once. */
    double grid[RATE_MAX + 3];
    Py_ssize_t g = 0;
    grid[g++] = t0;
    grid[g++] = t1;
    for (Py_ssize_t k = 0; k <= m; k++) {
        const double t = k < m ? ts[k] : t_cap;
        if (t0 < t && t < t1)
            grid[g++] = t;
    }
    for (Py_ssize_t i = 1; i < g; i++) /* insertion sort: a few values, nearly sorted */
        for (Py_ssize_t j = i; j > 0 && grid[j] < grid[j - 1]; j--) {
            const double x = grid[j];
            grid[j] = grid[j - 1];
            grid[j - 1] = x;
        }
    Py_ssize_t u = 0;
    for (Py_ssize_t i = 0; i < g; i++)
        if (u == 0 || grid[i] != grid[u - 1])
            grid[u++] = grid[i];
    double acc[3] = {0.0, 0.0, 0.0}, lo[3], hi[3];
    for (Py_ssize_t i = 0; i < u; i++) {
        /* The rate at grid[i] (timing._integrate's value). */
        const double t = grid[i];
        const Py_ssize_t k = bisect_right(ts, m, t) - 1;
        double *v = i == 0 ? lo : hi;
        if (k < 0) {
            memcpy(v, W[0], 24);
        } else if (k >= m - 1) {
            const double tau = py_min(py_max(t - t_last, 0.0), t_cap - t_last);
            for (int c = 0; c < 3; c++)
                v[c] = W[m - 1][c] + tau * slope[c];
        } else {
            const double ta = ts[k], tb = ts[k + 1];
            const double s = tb > ta ? (t - ta) / (tb - ta) : 1.0;
            for (int c = 0; c < 3; c++)
                v[c] = W[k][c] + s * (W[k + 1][c] - W[k][c]);
        }
        if (i == 0)
            continue;
        const double h = grid[i] - grid[i - 1];
        const double p[3] = {0.5 * (lo[0] + hi[0]) * h, 0.5 * (lo[1] + hi[1]) * h, 0.5 * (lo[2] + hi[2]) * h};
        if (magnus) {
            const double c = h * h / 12.0;
            const double x = 0.5 * (acc[1] * p[2] - acc[2] * p[1]) + c * (lo[1] * hi[2] - lo[2] * hi[1]);
            const double y = 0.5 * (acc[2] * p[0] - acc[0] * p[2]) + c * (lo[2] * hi[0] - lo[0] * hi[2]);
            const double z = 0.5 * (acc[0] * p[1] - acc[1] * p[0]) + c * (lo[0] * hi[1] - lo[1] * hi[0]);
            acc[0] += p[0] + x;
            acc[1] += p[1] + y;
            acc[2] += p[2] + z;
        } else {
            acc[0] += p[0];
            acc[1] += p[1];
            acc[2] += p[2];
        }
        memcpy(lo, hi, 24);
    }
    const double span = t1 - t0;
    const double mean[3] = {acc[0] / span, acc[1] / span, acc[2] / span};
    if (write_f8(a[4], 3, mean) < 0)
        return NULL;
    Py_RETURN_TRUE;
}

/* ---- one draw's SO(3) products and the §3 observers' sums (zswarm/math/so3.py exp, mul, apply on a
 * single vector or matrix; agent/algorithms/bearing_terms.py bearing_correction and position_rate): the
 * operations of the Python float code in the same order, so the same bits.  A sim or real agent's step
 * called them ~20 times a tick at 1-3 us each in Python (2026-12-06). */

/* so3.exp of one rotation vector (Rodrigues, its Taylor branch below |w|^2 = 1e-8). */
static void exp1(const double w[3], double E[9])
{
    const double x = w[0], y = w[1], z = w[2];
    const double t2 = x * x + y * y + z * z;
    double a, b;
    if (t2 < 1e-8) {
        a = 1.0 - t2 / 6.0;
        b = 0.5 - t2 / 24.0;
    } else {
        const double t = sqrt(t2);
        double sn, cs;
        sincos1(t, &sn, &cs);
        a = sn / t;
        b = (1.0 - cs) / t2;
    }
    const double bxy = b * x * y, bxz = b * x * z, byz = b * y * z;
    E[0] = 1.0 - b * (y * y + z * z), E[1] = bxy - a * z, E[2] = bxz + a * y;
    E[3] = bxy + a * z, E[4] = 1.0 - b * (x * x + z * z), E[5] = byz - a * x;
    E[6] = bxz - a * y, E[7] = byz + a * x, E[8] = 1.0 - b * (x * x + y * y);
}

static inline void mv3(const double *R, const double *v, double *out)
{
    for (int i = 0; i < 3; i++)
        out[i] = (R[3 * i] * v[0] + R[3 * i + 1] * v[1]) + R[3 * i + 2] * v[2];
}

/* exp1(w, out (3,3)) -> bool: so3.exp of a (3,) array; False: not one. */
static PyObject *py_exp1(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    double w[3], E[9];
    if (want_nargs(nargs, 2, "exp1") < 0)
        return NULL;
    if (!read_f8(a[0], 3, w))
        Py_RETURN_FALSE;
    exp1(w, E);
    if (write_f8(a[1], 9, E) < 0)
        return NULL;
    Py_RETURN_TRUE;
}

/* mul1(A, B, out (3,3)) -> bool: so3.mul of two (3, 3) arrays; False: not such. */
static PyObject *py_mul1(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    double A[9], Bm[9], C[9];
    if (want_nargs(nargs, 3, "mul1") < 0)
        return NULL;
    if (!read_f8(a[0], 9, A) || !read_f8(a[1], 9, Bm))
        Py_RETURN_FALSE;
    mm3(A, Bm, C);
    if (write_f8(a[2], 9, C) < 0)
        return NULL;
    Py_RETURN_TRUE;
}

/* apply1(R, v, out (3)) -> bool: so3.apply of a (3, 3) and a (3,) array; False: not such. */
static PyObject *py_apply1(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    double R[9], v[3], out[3];
    if (want_nargs(nargs, 3, "apply1") < 0)
        return NULL;
    if (!read_f8(a[0], 9, R) || !read_f8(a[1], 3, v))
        Py_RETURN_FALSE;
    mv3(R, v, out);
    if (write_f8(a[2], 3, out) < 0)
        return NULL;
    Py_RETURN_TRUE;
}

/* A number that is a Python float or int (not a bool, not an array of draws) as a double; 0: not one. */
static int plain_number(PyObject *o, double *x)
{
    if (PyFloat_CheckExact(o)) {
        *x = PyFloat_AS_DOUBLE(o);
        return 1;
    }
    if (PyLong_CheckExact(o)) {
        *x = PyLong_AsDouble(o);
        if (*x == -1.0 && PyErr_Occurred()) {
            PyErr_Clear();
            return 0;
        }
        return 1;
    }
    return 0;
}

/* An attribute of a neighbour's data: a (3,)/(3,3) array into x (n values); 0: absent or not such. */
static int nbr_f8(PyObject *nbr, const char *name, int n, double *x)
{
    PyObject *v = PyObject_GetAttrString(nbr, name);
    if (v == NULL) {
        PyErr_Clear();
        return 0;
    }
    const int ok = read_f8(v, n, x);
    Py_DECREF(v);
    return ok;
}

/* bearing_correction1(R, nbrs, out (3)) -> bool: bearing_terms.bearing_correction of one draw,
 * Σ_j k (−R̂_j b_nbr) × (R̂ b_own) from 0; False: a stack of draws or anything else, for the numpy. */
static PyObject *py_bearing_correction1(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    double R[9], s[3] = {0.0, 0.0, 0.0};
    if (want_nargs(nargs, 3, "bearing_correction1") < 0)
        return NULL;
    if (!read_f8(a[0], 9, R) || !PyTuple_CheckExact(a[1]))
        Py_RETURN_FALSE;
    for (Py_ssize_t q = 0; q < PyTuple_GET_SIZE(a[1]); q++) {
        PyObject *nbr = PyTuple_GET_ITEM(a[1], q);
        double Rj[9], bn[3], bo[3], k, u[3], v[3];
        PyObject *ko = PyObject_GetAttrString(nbr, "k");
        if (ko == NULL) {
            PyErr_Clear();
            Py_RETURN_FALSE;
        }
        const int kok = plain_number(ko, &k);
        Py_DECREF(ko);
        if (!kok || !nbr_f8(nbr, "R_hat_j", 9, Rj) || !nbr_f8(nbr, "b_nbr", 3, bn) || !nbr_f8(nbr, "b_own", 3, bo))
            Py_RETURN_FALSE;
        mv3(Rj, bn, u);
        mv3(R, bo, v);
        const double n0 = -u[0], n1 = -u[1], n2 = -u[2];
        const double c[3] = {n1 * v[2] - n2 * v[1], n2 * v[0] - n0 * v[2], n0 * v[1] - n1 * v[0]};
        for (int i = 0; i < 3; i++)
            s[i] = s[i] + k * c[i];
    }
    if (write_f8(a[2], 3, s) < 0)
        return NULL;
    Py_RETURN_TRUE;
}

/* position_rate1(R, p, sigma, k_p, nbrs, out (3)) -> bool: bearing_terms.position_rate of one draw,
 * −σ × p̂ − k_p Σ_j P_g (p̂ − p̂_j), g = R̂ b / |R̂ b| with b = b_pos or else b_own; False: not one draw. */
static PyObject *py_position_rate1(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    double R[9], p[3], sg[3], k_p, acc[3] = {0.0, 0.0, 0.0};
    if (want_nargs(nargs, 6, "position_rate1") < 0)
        return NULL;
    if (!read_f8(a[0], 9, R) || !read_f8(a[1], 3, p) || !read_f8(a[2], 3, sg) || !plain_number(a[3], &k_p) || !PyTuple_CheckExact(a[4]))
        Py_RETURN_FALSE;
    for (Py_ssize_t q = 0; q < PyTuple_GET_SIZE(a[4]); q++) {
        PyObject *nbr = PyTuple_GET_ITEM(a[4], q);
        double b[3], pj[3], g[3], d[3];
        PyObject *bp = PyObject_GetAttrString(nbr, "b_pos");
        if (bp == NULL) {
            PyErr_Clear();
            Py_RETURN_FALSE;
        }
        const int bok = bp == Py_None ? nbr_f8(nbr, "b_own", 3, b) : read_f8(bp, 3, b);
        Py_DECREF(bp);
        if (!bok || !nbr_f8(nbr, "p_hat_j", 3, pj))
            Py_RETURN_FALSE;
        mv3(R, b, g);
        const double norm = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        for (int i = 0; i < 3; i++) {
            g[i] = g[i] / norm;
            d[i] = p[i] - pj[i];
        }
        const double gd = g[0] * d[0] + g[1] * d[1] + g[2] * d[2];
        for (int i = 0; i < 3; i++)
            acc[i] = acc[i] + (d[i] - g[i] * gd);
    }
    const double c[3] = {sg[1] * p[2] - sg[2] * p[1], sg[2] * p[0] - sg[0] * p[2], sg[0] * p[1] - sg[1] * p[0]};
    double out[3];
    for (int i = 0; i < 3; i++)
        out[i] = -c[i] - k_p * acc[i];
    if (write_f8(a[5], 3, out) < 0)
        return NULL;
    Py_RETURN_TRUE;
}

/* finite_f8(a) -> True | False | None: every value of a contiguous float64 array finite (None: not such an array). */
static PyObject *py_finite_f8(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    if (want_nargs(nargs, 1, "finite_f8") < 0)
        return NULL;
    if (ndarray_type == NULL || (PyObject *)Py_TYPE(a[0]) != ndarray_type)
        Py_RETURN_NONE;
    Py_buffer b;
    if (PyObject_GetBuffer(a[0], &b, PyBUF_RECORDS_RO) < 0) {
        PyErr_Clear();
        Py_RETURN_NONE;
    }
    const char *f = b.format ? b.format : "B";
    if (*f == '<' || *f == '=' || *f == '@')
        f++;
    if (!(b.itemsize == 8 && f[0] == 'd' && f[1] == '\0' && PyBuffer_IsContiguous(&b, 'C'))) {
        PyBuffer_Release(&b);
        Py_RETURN_NONE;
    }
    const double *x = (const double *)b.buf;
    int ok = 1;
    for (Py_ssize_t k = 0; k < b.len / 8; k++)
        if (!isfinite(x[k]))
            ok = 0;
    PyBuffer_Release(&b);
    return PyBool_FromLong(ok);
}

/* ---- msgspec's hooks for the wire's arrays (zswarm/transport/messages.py enc_hook and dec_hook): an
 * array on the wire is [shape, bytes].  msgspec calls the hook once per array field, and a Python
 * hook cost a frame and a few calls each time (a tenth of a received message's decoding, 2026-12-06);
 * these do the usual cases without a frame and hand everything else to the Python hooks (set by
 * set_wire_hooks), so their results are the Python's: the same arrays, the same bytes. */
static PyObject *hook_frombuffer = NULL, *hook_f8 = NULL, *hook_dec_py = NULL, *hook_enc_py = NULL, *hook_kwnames = NULL,
                *hook_mat_shape = NULL, *hook_reshape = NULL;

/* set_wire_hooks(numpy.frombuffer, float64 dtype, dec_hook, enc_hook) */
static PyObject *py_set_wire_hooks(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    if (want_nargs(nargs, 4, "set_wire_hooks") < 0)
        return NULL;
    if (hook_kwnames == NULL) {
        hook_kwnames = Py_BuildValue("(s)", "dtype");
        hook_mat_shape = Py_BuildValue("(ii)", 3, 3);
        hook_reshape = PyUnicode_InternFromString("reshape");
        if (hook_kwnames == NULL || hook_mat_shape == NULL || hook_reshape == NULL)
            return NULL;
    }
    PyObject **slots[4] = {&hook_frombuffer, &hook_f8, &hook_dec_py, &hook_enc_py};
    for (int k = 0; k < 4; k++) {
        Py_INCREF(a[k]);
        Py_XSETREF(*slots[k], a[k]);
    }
    Py_RETURN_NONE;
}

/* 1: o is the exact int v. */
static int is_int(PyObject *o, long v)
{
    if (!PyLong_CheckExact(o))
        return 0;
    int overflow = 0;
    const long x = PyLong_AsLongAndOverflow(o, &overflow);
    return !overflow && x == v;
}

/* 3 or 9: obj is [shape, bytes] of a 3-vector ([3], 24 bytes) or a 3x3 matrix ([3, 3], 72 bytes),
 * the shape's entries exact ints, its bytes in *data; 0: not. */
static int wire_small(PyObject *obj, PyObject **data)
{
    if (!PyList_CheckExact(obj) || PyList_GET_SIZE(obj) != 2 || !PyList_CheckExact(PyList_GET_ITEM(obj, 0)) || !PyBytes_CheckExact(PyList_GET_ITEM(obj, 1)))
        return 0;
    PyObject *shape = PyList_GET_ITEM(obj, 0);
    *data = PyList_GET_ITEM(obj, 1);
    const Py_ssize_t nd = PyList_GET_SIZE(shape), len = PyBytes_GET_SIZE(*data);
    if (nd == 1 && len == 24 && is_int(PyList_GET_ITEM(shape, 0), 3))
        return 3;
    if (nd == 2 && len == 72 && is_int(PyList_GET_ITEM(shape, 0), 3) && is_int(PyList_GET_ITEM(shape, 1), 3))
        return 9;
    return 0;
}

/* The read-only float64 array over data of wire_small's n values, as dec_hook in Python makes it:
 * numpy.frombuffer(data, float64), reshaped to (3, 3) for 9 (a new reference; NULL: an error). */
static PyObject *wire_array(PyObject *data, int n)
{
    PyObject *args[2] = {data, hook_f8};
    PyObject *arr = PyObject_Vectorcall(hook_frombuffer, args, 1, hook_kwnames);
    if (arr == NULL || n == 3)
        return arr;
    PyObject *margs[2] = {arr, hook_mat_shape};
    PyObject *out = PyObject_VectorcallMethod(hook_reshape, margs, 2 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
    Py_DECREF(arr);
    return out;
}

/* dec_hook(type, obj): [[3], 24 bytes] -> frombuffer(bytes, float64); [[3, 3], 72 bytes] -> its
 * reshape(3, 3); anything else: the Python dec_hook's answer. */
static PyObject *py_dec_hook(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    if (want_nargs(nargs, 2, "dec_hook") < 0)
        return NULL;
    if (hook_dec_py == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "dec_hook: set_wire_hooks was not called");
        return NULL;
    }
    PyObject *data = NULL;
    const int n = ndarray_type != NULL && a[0] == ndarray_type ? wire_small(a[1], &data) : 0;
    return n ? wire_array(data, n) : PyObject_Vectorcall(hook_dec_py, a, 2, NULL);
}

/* enc_hook(obj): a C-contiguous native float64 numpy array -> [list(shape), its bytes]; anything
 * else: the Python enc_hook's answer. */
static PyObject *py_enc_hook(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    if (want_nargs(nargs, 1, "enc_hook") < 0)
        return NULL;
    if (hook_enc_py == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "enc_hook: set_wire_hooks was not called");
        return NULL;
    }
    Py_buffer b;
    if (!f8_buffer(a[0], &b))
        return PyObject_Vectorcall(hook_enc_py, a, 1, NULL);
    if (!PyBuffer_IsContiguous(&b, 'C')) {
        PyBuffer_Release(&b);
        return PyObject_Vectorcall(hook_enc_py, a, 1, NULL);
    }
    PyObject *shape = PyList_New(b.ndim);
    PyObject *data = shape ? PyBytes_FromStringAndSize((const char *)b.buf, b.len) : NULL;
    for (int k = 0; data != NULL && k < b.ndim; k++) {
        PyObject *d = PyLong_FromSsize_t(b.shape[k]);
        if (d == NULL)
            Py_CLEAR(data);
        else
            PyList_SET_ITEM(shape, k, d);
    }
    PyBuffer_Release(&b);
    PyObject *out = data != NULL ? PyList_New(2) : NULL;
    if (out == NULL) {
        Py_XDECREF(shape);
        Py_XDECREF(data);
        return NULL;
    }
    PyList_SET_ITEM(out, 0, shape);
    PyList_SET_ITEM(out, 1, data);
    return out;
}

/* named_decoded(v, envelope, max_open, max_name, max_abs) -> dict | None: message_checks._named of a
 * decoded map of named values when every value is a float or a decoded 3-vector or 3x3 matrix
 * ([shape, bytes]): the map it returns (the floats as they are, each array frombuffer's, read-only,
 * over the payload), each value within +-max_abs (NaN fails); None for anything else (a bad name, an
 * int, another shape, a value out of bounds), which the Python then checks and names.  Needs
 * set_wire_hooks. */
static PyObject *py_named_decoded(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    if (want_nargs(nargs, 5, "named_decoded") < 0)
        return NULL;
    const Py_ssize_t max_open = PyLong_AsSsize_t(a[2]), max_name = PyLong_AsSsize_t(a[3]);
    const double max_abs = PyFloat_AsDouble(a[4]);
    if (PyErr_Occurred())
        return NULL;
    PyObject *v = a[0], *envelope = a[1];
    if (hook_frombuffer == NULL || !PyDict_CheckExact(v) || PyDict_GET_SIZE(v) > max_open || !PyAnySet_Check(envelope))
        Py_RETURN_NONE;
    PyObject *out = PyDict_New();
    if (out == NULL)
        return NULL;
    Py_ssize_t pos = 0;
    PyObject *k, *x;
    while (PyDict_Next(v, &pos, &k, &x)) {
        if (!PyUnicode_CheckExact(k) || PyUnicode_GET_LENGTH(k) == 0 || PyUnicode_GET_LENGTH(k) > max_name)
            goto python;
        const int env = PySet_Contains(envelope, k);
        if (env < 0)
            goto fail;
        if (env)
            goto python;
        if (PyFloat_CheckExact(x)) {
            const double y = PyFloat_AS_DOUBLE(x);
            if (!(-max_abs <= y && y <= max_abs))
                goto python;
            if (PyDict_SetItem(out, k, x) < 0)
                goto fail;
            continue;
        }
        PyObject *data = NULL;
        const int n = wire_small(x, &data);
        if (!n)
            goto python;
        const double *d = (const double *)PyBytes_AS_STRING(data);
        for (int q = 0; q < n; q++) {
            double y;
            memcpy(&y, d + q, 8);
            if (!(fabs(y) <= max_abs))
                goto python;
        }
        PyObject *arr = wire_array(data, n);
        if (arr == NULL)
            goto fail;
        const int r = PyDict_SetItem(out, k, arr);
        Py_DECREF(arr);
        if (r < 0)
            goto fail;
    }
    return out;
python:
    Py_DECREF(out);
    Py_RETURN_NONE;
fail:
    Py_DECREF(out);
    return NULL;
}

/* ---- A decoded message's envelope and fixed fields at once (zswarm/transport/messages.py, Msg.__post_init__
 * and the kinds' _check): fields_ok(m, spec, version, max_id, max_seq, max_abs, unit_tol, rot_tol, max_ids)
 * -> bool.  True: m's envelope is as Msg.__post_init__ wants it (v == version an exact int, src an exact int in
 * [0, max_id], seq and inc exact ints in [0, max_seq), t an exact float within +-max_abs) and each field of
 * spec, a tuple of (name, code) pairs, passes: so the Python's checks would pass and leave every field as it
 * is (bar an id map's copy).  False: anything else, for the Python to check, convert and name. */
enum { F_VEC = 1, F_VEC_UNIT = 2, F_MAT_ROT = 3, F_MAP_VEC = 4, F_MAP_VEC_UNIT = 5, F_MAP_MAT_ROT = 6, F_FLOAT = 7, F_EMPTY = 8 };

static int attr_ok(PyObject *x, long code, double max_abs, double unit_tol, double rot_tol, long long max_id, Py_ssize_t max_ids)
{
    switch (code) {
    case F_VEC:
        return x == Py_None ? 1 : f8_check(x, 3, CHECK_NONE, max_abs, 0.0);
    case F_VEC_UNIT:
        return x == Py_None ? 1 : f8_check(x, 3, CHECK_UNIT, max_abs, unit_tol);
    case F_MAT_ROT:
        return x == Py_None ? 1 : f8_check(x, 9, CHECK_ROTATION, max_abs, rot_tol);
    case F_MAP_VEC:
    case F_MAP_VEC_UNIT:
    case F_MAP_MAT_ROT: {
        if (x == Py_None)
            return 1;
        if (!PyDict_CheckExact(x) || PyDict_GET_SIZE(x) > max_ids)
            return 0;
        const int n = code == F_MAP_MAT_ROT ? 9 : 3;
        const int check = code == F_MAP_VEC ? CHECK_NONE : code == F_MAP_VEC_UNIT ? CHECK_UNIT : CHECK_ROTATION;
        const double tol = code == F_MAP_VEC ? 0.0 : code == F_MAP_VEC_UNIT ? unit_tol : rot_tol;
        Py_ssize_t pos = 0;
        PyObject *k, *v;
        while (PyDict_Next(x, &pos, &k, &v)) {
            if (!PyLong_CheckExact(k))
                return 0;
            int overflow = 0;
            const long long j = PyLong_AsLongLongAndOverflow(k, &overflow);
            if (overflow || j < 0 || j > max_id)
                return 0;
            const int r = f8_check(v, n, check, max_abs, tol);
            if (r != 1)
                return r;
        }
        return 1;
    }
    case F_FLOAT:
        return PyFloat_CheckExact(x) && -max_abs <= PyFloat_AS_DOUBLE(x) && PyFloat_AS_DOUBLE(x) <= max_abs;
    case F_EMPTY:
        return (PyDict_CheckExact(x) && PyDict_GET_SIZE(x) == 0) || (PyList_CheckExact(x) && PyList_GET_SIZE(x) == 0);
    default:
        return 0;
    }
}

/* 1: the attribute `name` of m is an exact int in [lo, hi]. */
static int int_attr(PyObject *m, const char *name, long long lo, long long hi)
{
    PyObject *x = PyObject_GetAttrString(m, name);
    if (x == NULL) {
        PyErr_Clear();
        return 0;
    }
    int ok = 0;
    if (PyLong_CheckExact(x)) {
        int overflow = 0;
        const long long v = PyLong_AsLongLongAndOverflow(x, &overflow);
        ok = !overflow && lo <= v && v <= hi;
    }
    Py_DECREF(x);
    return ok;
}

static PyObject *py_fields_ok(PyObject *Py_UNUSED(self), PyObject *const *a, Py_ssize_t nargs)
{
    if (want_nargs(nargs, 9, "fields_ok") < 0)
        return NULL;
    PyObject *m = a[0], *spec = a[1];
    const long long version = PyLong_AsLongLong(a[2]), max_id = PyLong_AsLongLong(a[3]), max_seq = PyLong_AsLongLong(a[4]);
    const double max_abs = PyFloat_AsDouble(a[5]), unit_tol = PyFloat_AsDouble(a[6]), rot_tol = PyFloat_AsDouble(a[7]);
    const Py_ssize_t max_ids = PyLong_AsSsize_t(a[8]);
    if (PyErr_Occurred())
        return NULL;
    if (!PyTuple_CheckExact(spec)) {
        PyErr_SetString(PyExc_TypeError, "fields_ok: spec must be a tuple of (name, code)");
        return NULL;
    }
    if (!int_attr(m, "v", version, version) || !int_attr(m, "src", 0, max_id) || !int_attr(m, "seq", 0, max_seq - 1) || !int_attr(m, "inc", 0, max_seq - 1))
        Py_RETURN_FALSE;
    PyObject *t = PyObject_GetAttrString(m, "t");
    if (t == NULL) {
        PyErr_Clear();
        Py_RETURN_FALSE;
    }
    const int t_ok = attr_ok(t, F_FLOAT, max_abs, unit_tol, rot_tol, max_id, max_ids);
    Py_DECREF(t);
    if (!t_ok)
        Py_RETURN_FALSE;
    for (Py_ssize_t q = 0; q < PyTuple_GET_SIZE(spec); q++) {
        PyObject *item = PyTuple_GET_ITEM(spec, q);
        if (!PyTuple_CheckExact(item) || PyTuple_GET_SIZE(item) != 2) {
            PyErr_SetString(PyExc_TypeError, "fields_ok: spec must be a tuple of (name, code)");
            return NULL;
        }
        const long code = PyLong_AsLong(PyTuple_GET_ITEM(item, 1));
        if (code == -1 && PyErr_Occurred())
            return NULL;
        PyObject *x = PyObject_GetAttr(m, PyTuple_GET_ITEM(item, 0));
        if (x == NULL) {
            PyErr_Clear();
            Py_RETURN_FALSE;
        }
        const int r = attr_ok(x, code, max_abs, unit_tol, rot_tol, max_id, max_ids);
        Py_DECREF(x);
        if (r < 0)
            return NULL;
        if (!r)
            Py_RETURN_FALSE;
    }
    Py_RETURN_TRUE;
}

static PyMethodDef methods[] = {
    {"exp_batch", (PyCFunction)(void (*)(void))py_exp_batch, METH_FASTCALL, "exp_batch(W, E): Rodrigues' formula of n rotation vectors W (n,3) into E (n,3,3)."},
    {"rigid_step", (PyCFunction)(void (*)(void))py_rigid_step, METH_FASTCALL, "rigid_step(R, w, J_inv, tau, h, R_out, w_out): one implicit-midpoint step of n rigid bodies."},
    {"predict", (PyCFunction)(void (*)(void))py_predict, METH_FASTCALL, "predict(R_prev, R_now, ratio, out) -> left: R_now exp(ratio log(R_prev^T R_now)) of M draws (NaN and counted near pi)."},
    {"log_stack", (PyCFunction)(void (*)(void))py_log_stack, METH_FASTCALL, "log_stack(R, w) -> left: so3.log_batch of M matrices (NaN and counted near pi)."},
    {"terms", (PyCFunction)(void (*)(void))py_terms, METH_FASTCALL, "terms(A, K, u, R, out): the Terms of M draws of R (attitude_sync_terms), 15 rows of M."},
    {"sincos1", (PyCFunction)(void (*)(void))py_sincos1, METH_FASTCALL, "sincos1(x) -> (sin x, cos x) (zswarm/math/trig.py)."},
    {"sincos", (PyCFunction)(void (*)(void))py_sincos, METH_FASTCALL, "sincos(x, s, c): sin and cos of each x into s and c (zswarm/math/trig.py)."},
    {"flow_xi", (PyCFunction)(void (*)(void))py_flow_xi, METH_FASTCALL, "flow_xi(a0, b0, q0, a1, b1, q1, x, dt, k_xi, gamma, n): Heun sub-steps of (5.21) for M draws, x in place."},
    {"flow_xi_one", (PyCFunction)(void (*)(void))py_flow_xi_one, METH_FASTCALL, "flow_xi_one(a0, b0, q0, a1, b1, q1, xi, dt, k_xi, gamma, n) -> xi: flow_xi of one draw."},
    {"flow_aux", (PyCFunction)(void (*)(void))py_flow_aux, METH_FASTCALL, "flow_aux(Qt, zeta, table, rows, h, A, K, K2, u2, k_Q, k_zeta, gamma): the velocity-free filter, Qt and zeta in place."},
    {"f8_ok", (PyCFunction)(void (*)(void))py_f8_ok, METH_FASTCALL, "f8_ok(a, n, check, max_abs, tol) -> bool: a decoded (3,) or (3, 3) float64 array passes the wire's checks (zswarm/transport/message_checks.py)."},
    {"idmap_ok", (PyCFunction)(void (*)(void))py_idmap_ok, METH_FASTCALL, "idmap_ok(d, n, check, max_abs, tol, max_id, max_ids) -> bool: a decoded id map passes the wire's checks."},
    {"rate_integral", (PyCFunction)(void (*)(void))py_rate_integral, METH_FASTCALL, "rate_integral(samples, t0, t1, magnus, out) -> bool: timing._integrate of one rate vector a sample into out (False: not such samples)."},
    {"exp1", (PyCFunction)(void (*)(void))py_exp1, METH_FASTCALL, "exp1(w, out) -> bool: so3.exp of one rotation vector into out (3, 3) (False: not a (3,) float64 array)."},
    {"mul1", (PyCFunction)(void (*)(void))py_mul1, METH_FASTCALL, "mul1(A, B, out) -> bool: so3.mul of two 3x3 matrices into out (False: not such arrays)."},
    {"apply1", (PyCFunction)(void (*)(void))py_apply1, METH_FASTCALL, "apply1(R, v, out) -> bool: so3.apply of a 3x3 matrix to a 3-vector into out (False: not such arrays)."},
    {"bearing_correction1", (PyCFunction)(void (*)(void))py_bearing_correction1, METH_FASTCALL, "bearing_correction1(R, nbrs, out) -> bool: bearing_terms.bearing_correction of one draw (False: not one)."},
    {"position_rate1", (PyCFunction)(void (*)(void))py_position_rate1, METH_FASTCALL, "position_rate1(R, p, sigma, k_p, nbrs, out) -> bool: bearing_terms.position_rate of one draw (False: not one)."},
    {"finite_f8", (PyCFunction)(void (*)(void))py_finite_f8, METH_FASTCALL, "finite_f8(a) -> True | False | None: every value of a contiguous float64 array finite (None: not such an array)."},
    {"set_wire_hooks", (PyCFunction)(void (*)(void))py_set_wire_hooks, METH_FASTCALL, "set_wire_hooks(frombuffer, float64, dec_hook, enc_hook): what dec_hook and enc_hook call, and the Python hooks for what they do not do."},
    {"dec_hook", (PyCFunction)(void (*)(void))py_dec_hook, METH_FASTCALL, "dec_hook(type, obj): the wire's msgspec dec_hook (zswarm/transport/messages.py) for a 3-vector or 3x3 matrix, else the Python one."},
    {"enc_hook", (PyCFunction)(void (*)(void))py_enc_hook, METH_FASTCALL, "enc_hook(obj): the wire's msgspec enc_hook for a contiguous float64 array, else the Python one."},
    {"named_decoded", (PyCFunction)(void (*)(void))py_named_decoded, METH_FASTCALL, "named_decoded(v, envelope, max_open, max_name, max_abs) -> dict | None: the wire's check of decoded named values (floats, 3-vectors, 3x3 matrices), None for the Python to check."},
    {"fields_ok", (PyCFunction)(void (*)(void))py_fields_ok, METH_FASTCALL, "fields_ok(m, spec, version, max_id, max_seq, max_abs, unit_tol, rot_tol, max_ids) -> bool: a decoded message's envelope and the fields of spec pass the wire's checks as they are."},
    {"set_ndarray", (PyCFunction)(void (*)(void))py_set_ndarray, METH_FASTCALL, "set_ndarray(numpy.ndarray): the array type f8_ok and idmap_ok accept."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernels", "zswarm's compiled loops (zswarm/math/kernels.py calls them)", -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }

/* The FMU model of hevsim's native module thermal ROM FMU: a C translation of
 * hevsim.thermal.rom.RomStepper (implicit Euler of the reduced linear system
 *   dz/dt + (K_s + h K_w) z = B_q q + h B_w T_f + b_a T_amb + b_0
 * with the inputs at the end of the step) and of the ThermalRom output rows. The reduced
 * matrices come from model_data.h, generated from a ROM file (.rom.npz). SI units.
 *
 * Step: z_1 = (inv/dt) z_0 + inv B(h) u_1 with inv = (I/dt + K_s + h K_w)^-1, one product
 * [z_0, u_1] ST of the step matrix ST = [inv/dt | inv B(h)]^T (NZU x NZ, as RomStepper). For the
 * export's step DT_DESIGN and wall film H_DESIGN, ST_DESIGN is RomStepper's own matrix (computed
 * by numpy at export), so the FMU equals the Python ROM to the rounding of the product (a
 * vector-matrix product accumulated row by row, as BLAS's dgemv does); for another step
 * or film the instance computes ST itself (LU with partial pivoting, hv_step_matrices) and keeps
 * it (hv_cache) until dt or h changes. The state of an instance is z and the variables; the step
 * matrices are derived data.
 */
#ifndef HEVSIM_ROM_H
#define HEVSIM_ROM_H

#include <math.h>
#include <stdio.h>
#include <string.h>
#include "model_data.h"

#define NU (NCELL + NSEG + 2)  /* inputs of a step: heat, fluid per segment, ambient, 1 */
#define NZU (NZ + NU)

/* the complete state of an instance: plain data, copied and serialised byte for byte */
typedef struct {
    double r[N_VR]; /* Real variables, by value reference */
    double z[NZ];   /* reduced state */
    double time;
} hv_data;

/* the step matrix of the last (dt, h): st = [inv/dt | inv B(h)]^T */
typedef struct {
    int valid;
    double dt, h;
    double st[NZU][NZ];
    double lu[NZ][NZ];
    double inv[NZ][NZ];
    int piv[NZ];
} hv_cache;

static void hv_start(hv_data *d)
{
    int k;
    memset(d, 0, sizeof(*d));
    for (k = 0; k < N_VR; k++) d->r[k] = VAR_START[k];
}

static double hv_dot(const double *a, const double *b, int n)
{
    int i;
    double s = 0.0;
    for (i = 0; i < n; i++) s += a[i] * b[i];
    return s;
}

/* y[0..m-1] = x[0..n-1] a, a an n x m row-major matrix (accumulated row by row, so each y[j]
 * sums in the same order whatever the vector width the compiler uses) */
static void hv_vecmat(const double *x, int n, const double *a, int m, double *y)
{
    int i, j;
    for (j = 0; j < m; j++) y[j] = 0.0;
    for (i = 0; i < n; i++) {
        const double xi = x[i], *row = a + (size_t)i * (size_t)m;
        for (j = 0; j < m; j++) y[j] += xi * row[j];
    }
}

/* hot[c] = the largest candidate row G_j . z of cell c (each row summed in order in double, as
 * hv_vecmat does), evaluating in double only the rows that can be the largest (issue 26): every
 * row in single precision first, on the deviation d = z - T_ref u from the state of the uniform
 * field (T_ref = e.z / e.u, e the stored-heat row; G_j u = 1 to HS_ETA), so that
 * T_ref + G32_j d32 is within e_j = |G_j| E + c of the double value, with
 * E = HS_G32 |d| + HS_G64 (|z| + |T_ref| |u|) (HS_G32 = gamma_{NZ+2} in single precision: the
 * rounding of G and d to float and of the sum in any order; HS_G64: the double product and the
 * rounding of d) and c = 2 |T_ref| HS_ETA + 1e-12 K (1 % on both for their own rounding). A row
 * whose upper value T_ref + y32_j + e_j is below the largest lower value of its cell is below
 * the cell's largest double value, so the maximum over the others is exact (pack_run.py's
 * _module_hot_spots does the same) */
static void hv_hot_spots(const double *z, double *hot)
{
    int c, k, i, j;
    float d32[NZ], y32[NCELL * NCAND];
    double e_u = hv_dot(ENERGY, UNIT_STATE, NZ), t_ref = hv_dot(ENERGY, z, NZ) / e_u;
    double d_norm2 = 0.0, z_norm2 = 0.0, big_e, small_e;
    for (i = 0; i < NZ; i++) {
        double di = z[i] - t_ref * UNIT_STATE[i];
        d32[i] = (float)di;
        d_norm2 += di * di;
        z_norm2 += z[i] * z[i];
    }
    big_e = 1.01 * (HS_G32 * sqrt(d_norm2) + HS_G64 * (sqrt(z_norm2) + fabs(t_ref) * HS_UNIT_NORM));
    small_e = 1.01 * fabs(t_ref) * 2.0 * HS_ETA + 1e-12;
    for (j = 0; j < NCELL * NCAND; j++) y32[j] = 0.0f;
    for (i = 0; i < NZ; i++) {
        const float xi = d32[i], *row = CAND32_T[i];
        for (j = 0; j < NCELL * NCAND; j++) y32[j] += xi * row[j];
    }
    for (c = 0; c < NCELL; c++) {
        double low = -HUGE_VAL, best = -HUGE_VAL;
        for (k = 0; k < NCAND; k++) {
            j = c * NCAND + k;
            if (t_ref + (double)y32[j] - (CAND_NORM[j] * big_e + small_e) > low)
                low = t_ref + (double)y32[j] - (CAND_NORM[j] * big_e + small_e);
        }
        for (k = 0; k < NCAND; k++) {
            j = c * NCAND + k;
            if (t_ref + (double)y32[j] + (CAND_NORM[j] * big_e + small_e) >= low) {
                double v = hv_dot(OUT_CAND[j], z, NZ);
                if (v > best) best = v;
            }
        }
        hot[c] = best;
    }
}

/* the outputs of state z with the fluid temperatures fluid_k[NSEG] and ambient_k */
static void hv_outputs(hv_data *d, const double *fluid_k, double ambient_k)
{
    int s;
    double h = d->r[VR_WALL_H_W_M2K];
    double wall[NSEG];
    hv_vecmat(d->z, NZ, &OUT_MEAN_T[0][0], NCELL, &d->r[VR_CELL_MEAN_TEMP0]);
    hv_hot_spots(d->z, &d->r[VR_CELL_MAX_TEMP0]);
    hv_vecmat(d->z, NZ, &OUT_WALL_T[0][0], NSEG, wall);
    for (s = 0; s < NSEG; s++) {
        d->r[VR_SEGMENT_WALL_TEMP0 + s] = wall[s] / WALL_AREA[s];
        d->r[VR_SEGMENT_WALL_HEAT0 + s] = h * (wall[s] - WALL_AREA[s] * fluid_k[s]);
    }
    d->r[VR_AMBIENT_HEAT_W] = hv_dot(d->z, FILM_ROW, NZ) - B_AMB_TOTAL * ambient_k - F_CONST_TOTAL;
    d->r[VR_STORED_HEAT_J] = hv_dot(d->z, ENERGY, NZ);
}

/* the initial state: the uniform field initial_temp_k (exact: the constant is in the basis) */
static void hv_init(hv_data *d)
{
    int j;
    double t0 = d->r[VR_INITIAL_TEMP_K];
    for (j = 0; j < NZ; j++) d->z[j] = t0 * UNIT_STATE[j];
    hv_outputs(d, &d->r[VR_SEGMENT_FLUID_TEMP0], d->r[VR_AMBIENT_TEMP_K]);
}

/* cache->st for (dt, h), as RomStepper.set_wall_h: inv = (I/dt + (K_s + h K_w))^-1, st = [inv/dt | inv B(h)];
 * 0 on success, 1 if the matrix is singular */
static int hv_step_matrices(hv_cache *cache, double dt, double h)
{
    int i, j, k, p;
    double (*a)[NZ] = cache->lu;
    for (i = 0; i < NZ; i++)
        for (j = 0; j < NZ; j++) a[i][j] = (i == j ? 1.0 / dt : 0.0) + (K_SOLID[i][j] + h * K_WALL[i][j]);
    /* LU factorisation with partial pivoting (row swaps recorded in piv) */
    for (k = 0; k < NZ; k++) {
        double big = fabs(a[k][k]);
        p = k;
        for (i = k + 1; i < NZ; i++)
            if (fabs(a[i][k]) > big) {
                big = fabs(a[i][k]);
                p = i;
            }
        if (big == 0.0) return 1;
        cache->piv[k] = p;
        if (p != k)
            for (j = 0; j < NZ; j++) {
                double t = a[k][j];
                a[k][j] = a[p][j];
                a[p][j] = t;
            }
        for (i = k + 1; i < NZ; i++) {
            double f = a[i][k] / a[k][k];
            a[i][k] = f;
            for (j = k + 1; j < NZ; j++) a[i][j] -= f * a[k][j];
        }
    }
    /* inverse: solve A X = I column by column */
    for (j = 0; j < NZ; j++) {
        double col[NZ];
        for (i = 0; i < NZ; i++) col[i] = i == j ? 1.0 : 0.0;
        for (k = 0; k < NZ; k++)
            if (cache->piv[k] != k) {
                double t = col[k];
                col[k] = col[cache->piv[k]];
                col[cache->piv[k]] = t;
            }
        for (i = 0; i < NZ; i++)
            for (k = 0; k < i; k++) col[i] -= a[i][k] * col[k];
        for (i = NZ - 1; i >= 0; i--) {
            for (k = i + 1; k < NZ; k++) col[i] -= a[i][k] * col[k];
            col[i] /= a[i][i];
        }
        for (i = 0; i < NZ; i++) cache->inv[i][j] = col[i];
    }
    for (j = 0; j < NZ; j++) {
        for (i = 0; i < NZ; i++) cache->st[i][j] = cache->inv[j][i] / dt;
        for (k = 0; k < NU; k++) {
            double s = 0.0;
            for (i = 0; i < NZ; i++) {
                double b = k < NCELL ? B_HEAT[i][k]
                           : k < NCELL + NSEG ? h * B_WALL[i][k - NCELL]
                           : k == NCELL + NSEG ? B_AMB[i] : B_CONST[i];
                s += cache->inv[j][i] * b;
            }
            cache->st[NZ + k][j] = s;
        }
    }
    cache->dt = dt;
    cache->h = h;
    cache->valid = 1;
    return 0;
}

/* one communication step of dt [s] from time t [s]; 0 on success, 1 with a message (state unchanged) */
static int hv_do_step(hv_data *d, hv_cache *cache, double t, double dt, char *msg, size_t n)
{
    double zu[NZU];
    double h = d->r[VR_WALL_H_W_M2K];
    const double(*st)[NZ];
    if (!(dt > 0.0) || !isfinite(dt)) {
        snprintf(msg, n, "communication step size %g s: expected a positive number of seconds", dt);
        return 1;
    }
    if (dt == DT_DESIGN && h == H_DESIGN) {
        st = ST_DESIGN;
    } else {
        if (!cache->valid || cache->dt != dt || cache->h != h) {
            if (hv_step_matrices(cache, dt, h)) {
                cache->valid = 0;
                snprintf(msg, n, "the step matrix I/dt + K(h) is singular for dt = %g s, h = %g W/(m^2 K)", dt, h);
                return 1;
            }
        }
        st = (const double(*)[NZ])cache->st;
    }
    memcpy(zu, d->z, sizeof(d->z));
    memcpy(zu + NZ, &d->r[VR_CELL_HEAT0], NCELL * sizeof(double));
    memcpy(zu + NZ + NCELL, &d->r[VR_SEGMENT_FLUID_TEMP0], NSEG * sizeof(double));
    zu[NZ + NCELL + NSEG] = d->r[VR_AMBIENT_TEMP_K];
    zu[NZ + NCELL + NSEG + 1] = 1.0;
    hv_vecmat(zu, NZU, &st[0][0], NZ, d->z);
    hv_outputs(d, &d->r[VR_SEGMENT_FLUID_TEMP0], d->r[VR_AMBIENT_TEMP_K]);
    d->time = t + dt;
#ifdef VR_TIME
    d->r[VR_TIME] = d->time;
#endif
    return 0;
}

#endif

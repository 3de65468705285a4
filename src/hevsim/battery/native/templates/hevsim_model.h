/* The FMU model of hevsim's native cell/module FMUs: variables by value reference, the
 * initial state, one communication step (current or power input, one port temperature or
 * one per cell), the outputs and the domain checks. Shared by the FMI 2.0 and FMI 3.0
 * wrappers; mirrors hevsim.battery.fmu.CellStepper / ModuleStepper / current_for_power.
 */
#ifndef HEVSIM_MODEL_H
#define HEVSIM_MODEL_H

#include <stdio.h>
#include "model_data.h"
#include "hevsim_kernel.h"

/* the complete state of an instance: plain data, copied and serialised byte for byte */
typedef struct {
    double r[N_VR]; /* Real and Boolean (0/1) variables, by value reference */
    double p[N_CELLS][N_PRM];
    double x[N_CELLS][NX];
    double time;
} hv_data;

/* derived data kept by an instance besides its state: none for the cell model */
typedef struct {
    int unused;
} hv_cache;

/* HV_T_MIN_K, HV_T_MAX_K (model_data.h): temperature domain of the lumped cell model [K] */

/* HV_SOC_TOL (model_data.h): how far a state of charge may stray outside [0, 1] (round-off) */
static int hv_check_soc(const char *name, double soc, double t, double current, char *msg, size_t n)
{
    if (!(soc >= -HV_SOC_TOL && soc <= 1.0 + HV_SOC_TOL)) {
        snprintf(msg, n, "at t = %.17g s with a current of %.17g A the cell left its model's domain: "
                 "%s = %.17g outside [0, 1] (the current %s the cell)", t, current, name, soc,
                 soc < 0.0 ? "drained" : "overcharged");
        return 1;
    }
    return 0;
}

static double hv_soh(const double *p, const double *x)
{
    double ratio = (p[P_C0] + p[P_KCQ] * x[S_QABS]) / p[P_C0];
    return ratio / (1.0 * (1.0 - X_C)) - X_C / (1.0 - X_C);
}

/* start values of every variable */
static void hv_start(hv_data *d)
{
    int k;
    memset(d, 0, sizeof(*d));
    for (k = 0; k < N_VR; k++) d->r[k] = VAR_START[k];
}

/* the initial state from the current parameter values (exitInitializationMode, reset) */
static void hv_init(hv_data *d)
{
    int c, k;
    double ocv, rs, soh = 0.0;
    double soc0 = d->r[VR_SOC_INITIAL], temp0 = d->r[VR_TEMP_INITIAL_K];
    for (c = 0; c < N_CELLS; c++) {
        for (k = 0; k < N_PRM; k++) d->p[c][k] = PRM_BASE[k];
        d->p[c][P_C0] = d->r[VR_C0_C] * C0_SCALE[c];
        d->p[c][P_ALPHAC] = d->r[VR_ALPHA_C_PER_K];
        d->p[c][P_ALPHARS] = d->r[VR_ALPHA_RS_PER_K];
        d->p[c][P_CHEAT] = d->r[VR_C_HEAT_J_PER_K];
        d->p[c][P_RSKIN] = d->r[VR_R_SKIN_K_PER_W];
        d->p[c][P_RSCALE] = d->r[VR_R_SCALE] * R_SCALE[c];
        d->p[c][P_SOCINI] = soc0;
        for (k = 0; k < NX; k++) d->x[c][k] = 0.0;
        d->x[c][S_TEMP] = temp0;
        d->x[c][S_DIR] = 1.0;
        soh = c == 0 ? hv_soh(d->p[c], d->x[c]) : hv_min(soh, hv_soh(d->p[c], d->x[c]));
    }
    hv_ocv_rs(d->p[0], soc0, temp0, 1.0, &ocv, &rs);
    d->r[VR_VOLTAGE_V] = N_SER * ocv;
    d->r[VR_SOC] = soc0;
    d->r[VR_PORT_HEAT_W] = 0.0;
    d->r[VR_TEMP_K] = temp0;
    d->r[VR_SOH] = soh;
    d->r[VR_TERMINAL_CURRENT_A] = 0.0;
#if N_CELLS > 1
    for (c = 0; c < N_CELLS; c++) {
        d->r[VR_CELL_PORT_HEAT0 + c] = 0.0;
        d->r[VR_CELL_TEMP0 + c] = temp0;
    }
#endif
}

#if N_CELLS > 1
/* numpy's pairwise sum (used by ndarray.mean) of a[0..n-1], so the mean SOC rounds alike */
static double hv_pairwise_sum(const double *a, int n)
{
    int i, j;
    double r[8], res;
    if (n < 8) {
        res = 0.0;
        for (i = 0; i < n; i++) res += a[i];
        return res;
    }
    if (n <= 128) {
        for (j = 0; j < 8; j++) r[j] = a[j];
        for (i = 8; i < n - (n % 8); i += 8)
            for (j = 0; j < 8; j++) r[j] += a[i + j];
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) res += a[i];
        return res;
    } else {
        int n2 = n / 2;
        n2 -= n2 % 8;
        return hv_pairwise_sum(a, n2) + hv_pairwise_sum(a + n2, n - n2);
    }
}
#endif

/* step-average terminal voltage [V] of a step at current i_a, the state left unchanged */
static double hv_trial_voltage(const hv_data *d, double i_a, const double *t_port, double dt)
{
#if N_CELLS > 1
    double x[N_CELLS][NX], out_m[4], i_c[N_CELLS], soc_c[N_CELLS], heat_c[N_CELLS];
    memcpy(x, d->x, sizeof(x));
    hv_module_step((const double(*)[N_PRM])d->p, x, i_a, dt, t_port, out_m, i_c, soc_c, heat_c);
    return out_m[1];
#else
    double x[NX], rec[N_REC];
    memcpy(x, d->x[0], sizeof(x));
    hv_cell_step(d->p[0], x, i_a, dt, t_port[0], rec);
    return rec[R_VAVG];
#endif
}

/* the current [A] whose step-average power equals power_w [W] (hevsim.battery.fmu.current_for_power) */
static double hv_current_for_power(const hv_data *d, double power_w, const double *t_port, double dt)
{
    double i0, i1, f0, f1, i_new;
    int it;
    if (power_w == 0.0) return 0.0;
    i0 = power_w / hv_max(d->r[VR_VOLTAGE_V], 1e-6);
    i1 = i0 * 1.01;
    f0 = hv_trial_voltage(d, i0, t_port, dt) * i0 - power_w;
    f1 = hv_trial_voltage(d, i1, t_port, dt) * i1 - power_w;
    for (it = 0; it < 30; it++) {
        if (f1 == f0 || fabs(f1) <= 1e-12 * fabs(power_w)) break;
        i_new = i1 - f1 * (i1 - i0) / (f1 - f0);
        i0 = i1;
        i1 = i_new;
        f0 = f1;
        f1 = hv_trial_voltage(d, i1, t_port, dt) * i1 - power_w;
    }
    return i1;
}

static int hv_check_temp(const char *name, double t_k, char *msg, size_t n)
{
    if (!(t_k >= HV_T_MIN_K && t_k <= HV_T_MAX_K)) {
        snprintf(msg, n, "%s = %.17g K is outside the cell model's temperature range %g..%g K", name, t_k,
                 HV_T_MIN_K, HV_T_MAX_K);
        return 1;
    }
    return 0;
}

/* one communication step of dt [s] from time t [s]; 0 on success, 1 with a message (state unchanged) */
static int hv_do_step(hv_data *d, hv_cache *cache, double t, double dt, char *msg, size_t n)
{
    double t_port[N_CELLS], current;
    int c;
    (void)cache;
    if (!(dt > 0.0) || !isfinite(dt)) {
        snprintf(msg, n, "communication step size %g s: expected a positive number of seconds", dt);
        return 1;
    }
    for (c = 0; c < N_CELLS; c++) {
#if N_CELLS > 1
        if (d->r[VR_PER_CELL_PORTS] != 0.0) {
            t_port[c] = d->r[VR_CELL_PORT_TEMP0 + c];
            if (hv_check_temp(VAR_NAME[VR_CELL_PORT_TEMP0 + c], t_port[c], msg, n)) return 1;
            continue;
        }
#endif
        t_port[c] = d->r[VR_PORT_TEMP_K];
        if (hv_check_temp("port_temp_k", t_port[c], msg, n)) return 1;
    }
    if (d->r[VR_POWER_INPUT] != 0.0) {
        if (!isfinite(d->r[VR_POWER_W])) {
            snprintf(msg, n, "power_w = %g W is not a finite number", d->r[VR_POWER_W]);
            return 1;
        }
        current = hv_current_for_power(d, d->r[VR_POWER_W], t_port, dt);
    } else {
        current = d->r[VR_CURRENT_A];
    }
    if (!isfinite(current)) {
        snprintf(msg, n, "current_a = %g A is not a finite number", current);
        return 1;
    }
    {
#if N_CELLS > 1
        double x[N_CELLS][NX], out_m[4], i_c[N_CELLS], soc_c[N_CELLS], heat_c[N_CELLS];
        double t_hi = 0.0, soh = 0.0;
        memcpy(x, d->x, sizeof(x));
        hv_module_step((const double(*)[N_PRM])d->p, x, current, dt, t_port, out_m, i_c, soc_c, heat_c);
        if (!(out_m[0] > 0.0)) {
            snprintf(msg, n, "at t = %.17g s with a current of %.17g A the module left its model's domain: "
                     "voltage_v = %.17g V <= 0 (a current beyond the cells' short-circuit current)",
                     t + dt, current, out_m[0]);
            return 1;
        }
        for (c = 0; c < N_CELLS; c++) {
            char name[64];
            snprintf(name, sizeof(name), "cell%d soc", c);
            if (hv_check_soc(name, soc_c[c], t + dt, current, msg, n)) return 1;
            snprintf(name, sizeof(name), "cell%d temp_k", c);
            if (hv_check_temp(name, x[c][S_TEMP], msg, n)) return 1;
        }
        for (c = 0; c < N_CELLS; c++) {
            double temp1 = x[c][S_TEMP];
            double stored = d->p[c][P_CHEAT] * (temp1 - d->x[c][S_TEMP]);
            d->r[VR_CELL_PORT_HEAT0 + c] = heat_c[c] - stored / dt;
            d->r[VR_CELL_TEMP0 + c] = temp1;
            t_hi = c == 0 ? temp1 : hv_max(t_hi, temp1);
            soh = c == 0 ? hv_soh(d->p[c], x[c]) : hv_min(soh, hv_soh(d->p[c], x[c]));
        }
        memcpy(d->x, x, sizeof(x));
        d->r[VR_VOLTAGE_V] = out_m[0];
        d->r[VR_SOC] = hv_pairwise_sum(soc_c, N_CELLS) / N_CELLS;
        d->r[VR_PORT_HEAT_W] = out_m[3];
        d->r[VR_TEMP_K] = t_hi;
        d->r[VR_SOH] = soh;
#else
        double x[NX], rec[N_REC];
        memcpy(x, d->x[0], sizeof(x));
        hv_cell_step(d->p[0], x, current, dt, t_port[0], rec);
        if (!(rec[R_V] > 0.0)) {
            snprintf(msg, n, "at t = %.17g s with a current of %.17g A the cell left its model's domain: "
                     "voltage_v = %.17g V <= 0 (a current beyond the short-circuit current OCV/R_s = %.6g A)",
                     t + dt, current, rec[R_V], rec[R_OCV] / rec[R_RS]);
            return 1;
        }
        if (hv_check_soc("soc", rec[R_SOC], t + dt, current, msg, n)) return 1;
        if (hv_check_temp("temp_k", rec[R_TEMP], msg, n)) return 1;
        if (!(rec[R_CAP] > 0.0)) {
            snprintf(msg, n, "capacity %.17g C <= 0 (eq 35) at t = %.17g s", rec[R_CAP], t + dt);
            return 1;
        }
        memcpy(d->x[0], x, sizeof(x));
        d->r[VR_VOLTAGE_V] = rec[R_V];
        d->r[VR_SOC] = rec[R_SOC];
        d->r[VR_PORT_HEAT_W] = rec[R_PORT];
        d->r[VR_TEMP_K] = rec[R_TEMP];
        d->r[VR_SOH] = hv_soh(d->p[0], d->x[0]);
#endif
    }
    d->r[VR_CURRENT_A] = current;
    d->r[VR_TERMINAL_CURRENT_A] = current;
    d->time = t + dt;
#ifdef VR_TIME
    d->r[VR_TIME] = d->time;
#endif
    return 0;
}

#endif

/* Electro-thermal cell and module kernel of hevsim (thesis section 4.1.1, eqs 33-41), C99.
 *
 * A line-by-line translation of hevsim.battery.kernel (cell_step, branch_affine_at,
 * share_current, run_module, with the model options rc_persistent, ocv_in_step, the
 * charge-transfer overpotential and the one-state hysteresis) and hevsim.tables (interp1,
 * interp2 with clamping); the operations are kept in the same order so that the results equal
 * the Python kernel's to rounding. The model data (tables, RC sets, sizes) come from
 * model_data.h, generated from the parameter set. Sign convention: current > 0 discharges.
 */
#ifndef HEVSIM_KERNEL_H
#define HEVSIM_KERNEL_H

#include <math.h>
#include <string.h>

/* parameter vector of one cell (hevsim.battery.kernel.PARAMS without n_rc, a compile-time NRC) */
enum { P_C0, P_KCQ, P_ALPHAC, P_TREF, P_ALPHARS, P_CHEAT, P_RSKIN, P_VMIN, P_VMAX, P_SOCINI,
       P_RSCALE, P_BAND, P_RCPERS, P_OCVSTEP, P_CTI0, P_CTM, P_CTEA, P_HMAX, P_HGAMMA, P_EARS, P_HEA,
       P_ENTROPIC, N_PRM };

#define HV_R_GAS 8.314462618   /* molar gas constant [J/(mol K)], CODATA 2018 (kernel.R_GAS_J_PER_MOL_K) */
#define HV_FARADAY 96485.33212 /* Faraday constant [C/mol], CODATA 2018 (kernel.FARADAY_C_PER_MOL) */
/* state vector (hevsim.battery.kernel.STATES), then NRC discharge and NRC charge RC voltages */
enum { S_Q, S_QABS, S_TEMP, S_DIR, S_CYC, S_ILAST, S_HYST, N_FIXED };
#define NX (N_FIXED + 2 * NRC)
/* per-step record (hevsim.battery.kernel.RECORD, first entries) */
enum { R_V, R_VAVG, R_OCV, R_SOC, R_TEMP, R_HEAT, R_PORT, R_CAP, R_RS, N_REC };

static double hv_min(double a, double b) { return a < b ? a : b; }
static double hv_max(double a, double b) { return a > b ? a : b; }

/* Arrhenius factor exp(Ea / R_gas (1/T - 1/T_ref)) [-] (kernel.arrhenius) */
static double hv_arrhenius(double ea, double temp_k, double t_ref_k)
{
    return exp(ea / HV_R_GAS * (1.0 / temp_k - 1.0 / t_ref_k));
}

/* index i of the segment [xp[i], xp[i+1]] holding x (edge segments outside the range) */
static int hv_segment(const double *xp, int n, double x)
{
    int lo = 0, hi = n - 1, mid;
    if (x <= xp[0]) return 0;
    if (x >= xp[n - 1]) return n - 2;
    while (hi - lo > 1) {
        mid = (lo + hi) >> 1;
        if (xp[mid] <= x) lo = mid; else hi = mid;
    }
    return lo;
}

/* linear interpolation of fp[k * stride] over xp[k], clamped outside the range */
static double hv_interp1(const double *xp, int n, const double *fp, int stride, double x)
{
    int i;
    double w;
    if (n == 1) return fp[0];
    if (x <= xp[0]) return fp[0];
    if (x >= xp[n - 1]) return fp[(n - 1) * stride];
    i = hv_segment(xp, n, x);
    w = (x - xp[i]) / (xp[i + 1] - xp[i]);
    return fp[i * stride] + w * (fp[(i + 1) * stride] - fp[i * stride]);
}

/* bilinear interpolation of a [NSOC][NT] table at (soc, temp_k), clamped */
static double hv_interp2(const double fp[NSOC][NT], double x, double y)
{
    int i, j;
    double wx, wy, f0, f1;
    x = hv_min(hv_max(x, SOC_AX[0]), SOC_AX[NSOC - 1]);
    y = hv_min(hv_max(y, T_AX[0]), T_AX[NT - 1]);
    if (NSOC == 1) return hv_interp1(T_AX, NT, &fp[0][0], 1, y);
    if (NT == 1) return hv_interp1(SOC_AX, NSOC, &fp[0][0], NT, x);
    i = hv_segment(SOC_AX, NSOC, x);
    j = hv_segment(T_AX, NT, y);
    wx = (x - SOC_AX[i]) / (SOC_AX[i + 1] - SOC_AX[i]);
    wy = (y - T_AX[j]) / (T_AX[j + 1] - T_AX[j]);
    f0 = fp[i][j] + wy * (fp[i][j + 1] - fp[i][j]);
    f1 = fp[i + 1][j] + wy * (fp[i + 1][j + 1] - fp[i + 1][j]);
    return f0 + wx * (f1 - f0);
}

/* capacity C [C], eq (35), times the capacity-vs-temperature factor */
static double hv_capacity(const double *p, double qabs, double temp_k)
{
    double c = (p[P_C0] + p[P_KCQ] * qabs) * (1.0 + p[P_ALPHAC] * (temp_k - p[P_TREF]));
    return c * hv_interp1(T_AX, NT, CAPF, 1, temp_k);
}

/* OCV [V] (clamped to the voltage limits) and R_s [ohm] (eq 36) of a direction (+1 discharge) */
static void hv_ocv_rs(const double *p, double soc, double temp_k, double direction, double *ocv, double *rs)
{
    double o, r;
    if (direction >= 0.0) {
        o = hv_interp2(OCV_D, soc, temp_k);
        r = hv_interp2(RS_D, soc, temp_k);
    } else {
        o = hv_interp2(OCV_C, soc, temp_k);
        r = hv_interp2(RS_C, soc, temp_k);
    }
    *ocv = hv_min(hv_max(o, p[P_VMIN]), p[P_VMAX]);
    if (p[P_EARS] != 0.0) r *= hv_arrhenius(p[P_EARS], temp_k, p[P_TREF]);
    *rs = r * p[P_RSCALE] * (1.0 + p[P_ALPHARS] * (temp_k - p[P_TREF]));
}

/* OCV [V] of a direction at (soc, temp_k), clamped to the voltage limits (kernel.cell_ocv) */
static double hv_cell_ocv(const double *p, double soc, double temp_k, double direction)
{
    double o = direction >= 0.0 ? hv_interp2(OCV_D, soc, temp_k) : hv_interp2(OCV_C, soc, temp_k);
    return hv_min(hv_max(o, p[P_VMIN]), p[P_VMAX]);
}

/* entropic coefficient dU/dT [V/K]: temperature slope of a direction's OCV table (kernel.ocv_dudt) */
static double hv_ocv_dudt(const double *p, double soc, double temp_k, double direction)
{
    const double(*tab)[NT] = direction >= 0.0 ? OCV_D : OCV_C;
    double raw, s, lo, hi;
    int j;
    if (NT < 2 || temp_k < T_AX[0] || temp_k >= T_AX[NT - 1]) return 0.0;
    raw = hv_interp2(tab, soc, temp_k);
    if (!(p[P_VMIN] < raw && raw < p[P_VMAX])) return 0.0;
    j = hv_segment(T_AX, NT, temp_k);
    s = hv_min(hv_max(soc, SOC_AX[0]), SOC_AX[NSOC - 1]);
    lo = hv_interp1(SOC_AX, NSOC, &tab[0][j], NT, s);
    hi = hv_interp1(SOC_AX, NSOC, &tab[0][j + 1], NT, s);
    return (hi - lo) / (T_AX[j + 1] - T_AX[j]);
}

/* mean OCV [V] over the linear SOC path soc0 -> soc1 with end OCVs f0, f1 (kernel.ocv_step_mean) */
static double hv_ocv_step_mean(const double *p, double soc0, double soc1, double f0, double f1, double temp_k,
                               double direction)
{
    double lo, hi, f, f_prev, f_hi, acc = 0.0, s_prev;
    int k;
    if (soc1 == soc0) return f0;
    if (soc0 < soc1) {
        lo = soc0; f_prev = f0; hi = soc1; f = f1;
    } else {
        lo = soc1; f_prev = f1; hi = soc0; f = f0;
    }
    f_hi = f;
    s_prev = lo;
    for (k = 0; k < NSOC; k++) {
        double s = SOC_AX[k];
        if (lo < s && s < hi) {
            f = hv_cell_ocv(p, s, temp_k, direction);
            acc += 0.5 * (f + f_prev) * (s - s_prev);
            s_prev = s;
            f_prev = f;
        }
    }
    acc += 0.5 * (f_hi + f_prev) * (hi - s_prev);
    return acc / (hi - lo);
}

/* charge-transfer overpotential eta [V] and d eta / d i [ohm] (kernel.ct_overpotential) */
static void hv_ct_overpotential(const double *p, double i_a, double temp_k, double *eta, double *d_eta)
{
    double i0, b, u;
    if (p[P_CTI0] <= 0.0) {
        *eta = 0.0;
        *d_eta = 0.0;
        return;
    }
    i0 = p[P_CTI0] / p[P_RSCALE];
    if (p[P_CTEA] != 0.0) i0 *= exp(-p[P_CTEA] / HV_R_GAS * (1.0 / temp_k - 1.0 / p[P_TREF]));
    b = p[P_CTM] * 2.0 * HV_R_GAS * temp_k / HV_FARADAY;
    u = i_a / (2.0 * i0);
    *eta = b * asinh(u);
    *d_eta = b / (2.0 * i0 * sqrt(1.0 + u * u));
}

/* one-state hysteresis over a step at constant i_a: end value and step mean [V] (kernel.hysteresis_step) */
static void hv_hysteresis_step(const double *p, double h0, double i_a, double dt, double cap, double temp_k,
                               double *h1, double *h_avg)
{
    double target, k, e1, d, m;
    *h1 = h0;
    *h_avg = h0;
    if (p[P_HMAX] <= 0.0 || i_a == 0.0) return;
    m = p[P_HMAX];
    if (p[P_HEA] != 0.0) m *= hv_arrhenius(p[P_HEA], temp_k, p[P_TREF]);
    target = i_a > 0.0 ? -m : m;
    k = p[P_HGAMMA] * fabs(i_a) / cap;
    if (k <= 0.0) return;
    e1 = exp(-k * dt);
    d = h0 - target;
    *h1 = target + d * e1;
    *h_avg = target + d * (1.0 - e1) / (k * dt);
}

/* +1 discharge, -1 charge; inside the dead band the last direction is kept */
static double hv_direction(double i_a, double last, double band)
{
    if (i_a > band) return 1.0;
    if (i_a < -band) return -1.0;
    return last;
}

/* number of RC states in use: NRC with a persistent set, else 2 NRC (switched sets) */
#define HV_N_RC_STATES(p) ((p)[P_RCPERS] > 0.0 ? NRC : 2 * NRC)

/* RC state j at temp_k: resistance [ohm, unscaled], time constant [s] with their Arrhenius laws,
 * connected? (kernel.rc_element, kernel.rc_values) */
static void hv_rc(const double *p, int j, double direction, double temp_k, double *r, double *tau, int *active)
{
    const double *row;
    if (p[P_RCPERS] > 0.0) {
        row = direction > 0.0 ? RC_D[j] : RC_C[j];
        *active = 1;
    } else if (j < NRC) {
        row = RC_D[j];
        *active = direction > 0.0;
    } else {
        row = RC_C[j - NRC];
        *active = direction < 0.0;
    }
    *r = row[0];
    *tau = row[1];
    if (row[2] != 0.0) *r *= hv_arrhenius(row[2], temp_k, p[P_TREF]);
    if (row[3] != 0.0) *tau *= hv_arrhenius(row[3], temp_k, p[P_TREF]);
}

/* advance cell state x by dt [s] at constant current i_a [A], port temperature t_port [K] */
static void hv_cell_step(const double *p, double *x, double i_a, double dt, double t_port, double *rec)
{
    int j, active;
    double direction = hv_direction(i_a, x[S_DIR], p[P_BAND]);
    double temp0 = x[S_TEMP];
    double cap = hv_capacity(p, x[S_QABS], temp0);
    double soc = p[P_SOCINI] - x[S_Q] / cap;
    double ocv, rs, ocv_avg, eta, d_eta, h1, h_avg;
    double v_sum_end = 0.0, v_sum_avg = 0.0, rc_heat_j = 0.0;
    double heat_j, q_heat, tau_th, t_inf, temp1, port_j, v_avg, v_end;
    if (p[P_OCVSTEP] > 0.0) { /* OCV consistent within the step */
        double soc1 = soc - i_a * dt / cap, f0, unused;
        f0 = hv_cell_ocv(p, soc, temp0, direction);
        ocv = hv_cell_ocv(p, soc1, temp0, direction);
        ocv_avg = hv_ocv_step_mean(p, soc, soc1, f0, ocv, temp0, direction);
        hv_ocv_rs(p, 0.5 * (soc + soc1), temp0, direction, &unused, &rs);
    } else {
        hv_ocv_rs(p, soc, temp0, direction, &ocv, &rs);
        ocv_avg = ocv;
    }
    for (j = 0; j < HV_N_RC_STATES(p); j++) {
        double r0, tau, r_j, a, v0, e1, d, v1, int_v, int_v2;
        hv_rc(p, j, direction, temp0, &r0, &tau, &active);
        r_j = r0 * p[P_RSCALE];
        a = active ? r_j * i_a : 0.0;
        v0 = x[N_FIXED + j];
        e1 = exp(-dt / tau);
        d = v0 - a;
        v1 = a + d * e1;
        int_v = a * dt + d * tau * (1.0 - e1);
        int_v2 = a * a * dt + 2.0 * a * d * tau * (1.0 - e1) + d * d * 0.5 * tau * (1.0 - e1 * e1);
        rc_heat_j += int_v2 / r_j;
        if (active) {
            v_sum_end += v1;
            v_sum_avg += int_v / dt;
        }
        x[N_FIXED + j] = v1;
    }
    hv_ct_overpotential(p, i_a, temp0, &eta, &d_eta);
    hv_hysteresis_step(p, x[S_HYST], i_a, dt, cap, temp0, &h1, &h_avg);
    heat_j = rs * i_a * i_a * dt + rc_heat_j;
    if (p[P_CTI0] > 0.0 || p[P_HMAX] > 0.0) heat_j += (eta - h_avg) * i_a * dt;
    if (p[P_ENTROPIC] > 0.0) { /* reversible heat -i T dU/dT (kernel.cell_step) */
        double s_rev = p[P_OCVSTEP] > 0.0 ? soc - 0.5 * i_a * dt / cap : soc;
        heat_j -= i_a * (temp0 * hv_ocv_dudt(p, s_rev, temp0, direction)) * dt;
    }
    q_heat = heat_j / dt;
    /* lumped temperature, eq (41) with a skin resistance to the port: exact exponential */
    tau_th = p[P_CHEAT] * p[P_RSKIN];
    t_inf = t_port + q_heat * p[P_RSKIN];
    temp1 = t_inf + (temp0 - t_inf) * exp(-dt / tau_th);
    port_j = heat_j - p[P_CHEAT] * (temp1 - temp0);
    /* charge, eqs (33), (34), (38) */
    x[S_Q] += i_a * dt;
    x[S_QABS] += fabs(i_a) * dt;
    x[S_CYC] += fabs(i_a) * dt / (2.0 * cap);
    x[S_TEMP] = temp1;
    x[S_DIR] = direction;
    x[S_ILAST] = i_a;
    x[S_HYST] = h1;
    v_avg = ocv_avg - rs * i_a - v_sum_avg;
    v_end = ocv - rs * i_a - v_sum_end;
    if (p[P_CTI0] > 0.0 || p[P_HMAX] > 0.0) {
        v_avg += h_avg - eta;
        v_end += h1 - eta;
    }
    rec[R_V] = v_end;
    rec[R_VAVG] = v_avg;
    rec[R_OCV] = ocv;
    rec[R_SOC] = p[P_SOCINI] - x[S_Q] / cap;
    rec[R_TEMP] = temp1;
    rec[R_HEAT] = q_heat;
    rec[R_PORT] = port_j / dt;
    rec[R_CAP] = cap;
    rec[R_RS] = rs;
}

#if N_CELLS > 1
/* step-average terminal voltage of a branch as E - Z i for a current of direction `direction`,
 * linearised at the current i_lin [A] (kernel.branch_affine_at; exact for the affine parts) */
static void hv_branch_affine(const double *p, const double *x, double dt, double direction, double i_lin, double *e,
                             double *z)
{
    int j, active;
    double temp = x[S_TEMP];
    double cap = hv_capacity(p, x[S_QABS], temp);
    double soc = p[P_SOCINI] - x[S_Q] / cap;
    double ocv, rs;
    if (p[P_OCVSTEP] > 0.0) {
        double soc1 = soc - i_lin * dt / cap, f0, f1, ocv_avg, z_ocv, unused;
        f0 = hv_cell_ocv(p, soc, temp, direction);
        f1 = hv_cell_ocv(p, soc1, temp, direction);
        ocv_avg = hv_ocv_step_mean(p, soc, soc1, f0, f1, temp, direction);
        hv_ocv_rs(p, 0.5 * (soc + soc1), temp, direction, &unused, &rs);
        if (fabs(soc1 - soc) > 1e-9) {
            z_ocv = dt / cap * (f1 - ocv_avg) / (soc1 - soc);
        } else { /* half the local slope on the side the SOC moves to */
            double ds = -1e-6 * direction;
            f1 = hv_cell_ocv(p, soc + ds, temp, direction);
            z_ocv = 0.5 * dt / cap * (f1 - ocv_avg) / ds;
        }
        *e = ocv_avg + z_ocv * i_lin;
        *z = rs + z_ocv;
    } else {
        hv_ocv_rs(p, soc, temp, direction, &ocv, &rs);
        *e = ocv;
        *z = rs;
    }
    for (j = 0; j < HV_N_RC_STATES(p); j++) {
        double r0, tau, g;
        hv_rc(p, j, direction, temp, &r0, &tau, &active);
        g = tau * (1.0 - exp(-dt / tau)) / dt;
        if (active) {
            *e -= x[N_FIXED + j] * g;
            *z += r0 * p[P_RSCALE] * (1.0 - g);
        }
    }
    if (p[P_CTI0] > 0.0) {
        double eta, d_eta;
        hv_ct_overpotential(p, i_lin, temp, &eta, &d_eta);
        *e -= eta - d_eta * i_lin;
        *z += d_eta;
    }
    if (p[P_HMAX] > 0.0) {
        double h1, h_avg;
        hv_hysteresis_step(p, x[S_HYST], i_lin, dt, cap, temp, &h1, &h_avg);
        *e += h_avg;
    }
}

/* branch currents i_out[b] of the N_PAR parallel cells first..first+N_PAR-1 carrying i_total
 * (kernel.share_current: exact for the affine model; relinearised with the nonlinear options) */
static void hv_share_current(const double p[][N_PRM], const double x[][NX], int first, double i_total, double dt,
                             double *i_out)
{
    int b, it, nonlinear = 0;
    double dirs[N_PAR], e[N_PAR], z[N_PAR];
    double v, s_g, s_eg;
    for (b = 0; b < N_PAR; b++) {
        const double *pb = p[first + b];
        dirs[b] = hv_direction(i_total, x[first + b][S_DIR], pb[P_BAND]);
        i_out[b] = i_total / N_PAR;
        if (pb[P_OCVSTEP] > 0.0 || pb[P_CTI0] > 0.0 || pb[P_HMAX] > 0.0) nonlinear = 1;
    }
    for (it = 0; it < N_PAR + 2 + (nonlinear ? 50 : 0); it++) {
        int flipped = 0;
        double change = 0.0;
        s_g = 0.0;
        s_eg = 0.0;
        for (b = 0; b < N_PAR; b++) {
            hv_branch_affine(p[first + b], x[first + b], dt, dirs[b], i_out[b], &e[b], &z[b]);
            s_g += 1.0 / z[b];
            s_eg += e[b] / z[b];
        }
        v = (s_eg - i_total) / s_g;
        for (b = 0; b < N_PAR; b++) {
            double d_new, i_new = (e[b] - v) / z[b];
            change = hv_max(change, fabs(i_new - i_out[b]));
            i_out[b] = i_new;
            d_new = hv_direction(i_out[b], x[first + b][S_DIR], p[first + b][P_BAND]);
            if (d_new != dirs[b]) {
                dirs[b] = d_new;
                flipped = 1;
            }
        }
        if (!flipped && (!nonlinear || change < 1e-9 * (1.0 + fabs(i_total)))) break;
    }
}

/* one step of the module (hevsim.battery.kernel.run_module for one sample):
 * out_m = (voltage end [V], voltage average [V], heat [W], port heat [W]);
 * cell c: i_cell [A], soc_cell [-], heat_cell [W] (temperature is x[c][S_TEMP]) */
static void hv_module_step(const double p[][N_PRM], double x[][NX], double current, double dt,
                           const double *t_port, double *out_m, double *i_cell, double *soc_cell,
                           double *heat_cell)
{
    int s, b;
    double rec[N_REC], i_b[N_PAR];
    double v_end = 0.0, v_avg = 0.0, heat = 0.0, port = 0.0;
    for (s = 0; s < N_SER; s++) {
        double v_group = 0.0, v_group_avg = 0.0;
        int first = s * N_PAR;
        hv_share_current(p, (const double(*)[NX])x, first, current, dt, i_b);
        for (b = 0; b < N_PAR; b++) {
            int c = first + b;
            hv_cell_step(p[c], x[c], i_b[b], dt, t_port[c], rec);
            v_group += rec[R_V] / N_PAR;
            v_group_avg += rec[R_VAVG] / N_PAR;
            heat += rec[R_HEAT];
            port += rec[R_PORT];
            i_cell[c] = i_b[b];
            soc_cell[c] = rec[R_SOC];
            heat_cell[c] = rec[R_HEAT];
        }
        v_end += v_group;
        v_avg += v_group_avg;
    }
    out_m[0] = v_end;
    out_m[1] = v_avg;
    out_m[2] = heat;
    out_m[3] = port;
}
#endif

#endif

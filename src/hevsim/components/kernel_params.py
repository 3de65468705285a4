"""The layout of the vehicle kernel's scalar parameter vector ``p`` (one float per name).

The series HEV's point kernels (:mod:`hevsim.architectures.series_kernel`) read it; the layout
lives in the physics layer, below the architectures and the simulator that fill it (issue 24:
constants shared across layers live in the lower one). The battery model's step limits and bus
load are not in it: the one loop hands them to the plug-in each step
(:func:`hevsim.sim._loop.battery_begin`).
"""

PARAMS = (
    "mass_kg", "mass_factor", "cd", "area_m2", "rho_kgpm3", "headwind_mps", "crr", "crr_v",
    "tire_radius_m", "gear_ratio", "gear_efficiency", "max_brake_force_n",
    "driver_gain_per_mps", "driver_feedforward",
    "motor_kind", "motor_eff", "motor_scale", "motor_inertia",
    "gen_kind", "gen_eff", "gen_scale", "gen_inertia",
    "engine_present", "engine_use_tmap", "engine_use_fuel_map", "engine_stall_radps",
    "engine_redline_radps", "engine_scale", "engine_inertia", "engine_lhv_jpkg",
    "bat_ns", "bat_np", "bat_r_extra", "bat_capacity_ah", "bat_coulombic_eff",
    "bat_max_dis_a", "bat_max_chg_a", "bat_temp_k", "soc_initial", "soc_min", "soc_max",
    "genset_kind", "soc_low", "soc_high", "soc_boost", "genset_speed_radps",
    "genset_start_speed_radps", "throttle_run", "throttle_boost", "genset_gain_per_radps",
    "genset_current_a", "regen_min_speed_mps", "aux_power_w", "pure_ice_band_w",
    "driver_kind", "supervisor_kind",
)  # fmt: skip
P = {name: i for i, name in enumerate(PARAMS)}

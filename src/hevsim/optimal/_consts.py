"""Constants shared by the DP kernels and the Python driver (no numba import here)."""

MODE_PLAIN = 0  # plain cost-to-go: hard wall or linear penalty
MODE_LEVELSET = 1  # admissible iff the interpolated level-set function is <= VTOL
MODE_BAND = 2  # one state: admissible iff between the boundary lines

ST_FEASIBLE = 0  # at least one admissible input with a finite cost
ST_MASKED = 1  # every input is rejected by the model's infeasibility mask (or infinite cost)
ST_BOUNDS = 2  # every unmasked input drives the state outside the grid
ST_UNREACHABLE = 3  # no in-bounds input leads to a state from which the target is reachable
ST_BAD = 4  # the model returned NaN / infinite next state / -inf cost for an unmasked pair

WSNAP = 1e-12  # interpolation weights closer than this to 0 or 1 are snapped
BTOL = 1e-9  # relative tolerance (of the grid span) on the state bounds
VTOL = 1e-9  # level-set tolerance (span-normalised distance) for "inside the set"
VTIE = 1e-12  # level values closer than this are a tie (broken by the lower cost)
V_CAP = 1.0e6  # level-set value of nodes whose every input is masked
FWD_VTIE = 1e-6  # forward pass, level set: next level values this close to the smallest are a tie

"""Named slots shared by the step loop, the effects and the post-processing (a leaf module).

The step loop keeps its energy accumulators in one float64 array (``State.acc``) and writes one
history row per ``history_every`` steps; these constants name the slots and columns once, so every
module that reads or writes them agrees. Node fixity is a bit mask per node, and the kernels report
why a run stopped with a status code.
"""

# energy accumulators (State.acc, float64), J
ACC_WK = 0   # prescribed-motion work (plates, drives, clamps)
ACC_VD = 1   # damping dissipation
ACC_PW = 2   # contact penalty work (planes + fiber–fiber contact hook)
ACC_FD = 3   # friction dissipation (contact hook)
ACC_WF = 4   # work of the friction forces on the fibers (contact hook; part of ACC_PW)
ACC_STORED = 5  # stored contact energy at t_n (plane penalties + the hook's potential and springs): a state
ACC_STORED0 = 6  # the hook's stored energy at the first step a run evaluates (−1 until then; a sentinel fastmath keeps, unlike NaN): the residual's start
# not an energy: the largest |v_{n+½}|² of the nodes [m²/s²] after the step loop's last update, −1
# until the first update of each step-loop call; the contact hook's path bound reads it
ACC_V2_MAX = 7
# the second half of the friction forces' work over the last update, ½Δt f_n·v_{n+½}, which the next
# step books to ACC_WF and ACC_FD with its own first half ½Δt f_{n+1}·v_{n+½}: the sum over the same
# displacement the friction springs' energy changes by (their energy is booked at t_{n+1})
ACC_WF_NEXT = 8
ACC_SIZE = 9

# history columns (one row per recorded step)
H_TIME = 0
H_PLATE_DISP = 1   # 2 columns: lower, upper plate travel, m
H_PLATE_FORCE = 3  # 2 columns: lower, upper plate reaction, N
H_KE = 5
H_SE = 6
H_VD = 7
H_WK = 8
H_PW = 9
H_FD = 10
H_CONTACTS = 11
H_WF = 12          # work of the friction forces on the fibers (ACC_WF), J
H_STORED = 13      # stored contact energy at t_n (ACC_STORED), J
H_KE_LF = 14       # ½ v_{n−½}·M v_{n+½} + rotations, the kinetic term central differences conserve, J
H_SEGMENT = 15     # the entry of scene.loading.path the plates are in (0 for the one-segment loading; a hold counts with the move before it)
H_VD_LF = 16       # the damping dissipation in step with H_KE_LF (ALLVD to t_{n−1} + ½αΔt v_{n−½}·M v̄_n), J
H_WALL = 17        # one column per wall plane from here on, N (the fixed slots above come first)

# node fixity bits (SceneArrays.fix_mask)
FIX_X = 1
FIX_Y = 2
FIX_Z = 4
FIX_ROT = 8
DRIVEN = 16

# why the step loop stopped
STATUS_OK = 0
STATUS_NAN = 1
STATUS_SPEED = 2
STATUS_RUNAWAY = 3
STATUS_ENERGY = 4
STATUS_PENETRATION = 5  # a node deep in a plate or wall (checked between the step loop's calls)
STATUS_LEFT_BOX = 6     # a node beyond a plate or wall (checked between the step loop's calls)


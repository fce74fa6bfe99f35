"""The contact hook's data as named structures (NamedTuples of arrays; a leaf module).

:func:`fiberpipe.solver.terms.contact.contact_step` receives one :class:`ContactData`:

- ``params`` (:class:`ContactParams`): the law and the friction settings, constant over a run;
- ``stats`` (:class:`ContactStats`): counters and last-step figures, each a 1-element array so the
  kernel can update it in place;
- ``segs`` (:class:`Segments`): the fibers' segments (one per beam element);
- ``lists``: a numba typed list of two :class:`PairList` — the Verlet list in use and the spare that
  the next build fills; each carries the per-pair histories that must follow the pairs across a
  rebuild (friction springs, initial-overlap offsets);
- ``records``: a typed list holding one :class:`PairRecords` — this step's per-pair results;
- ``fc``: the hook's force array (the step loop adds it to the nodes and clears it);
- ``ff``: the scene's friction force array (``SceneArrays.friction_forces``), which the step loop's
  update applies and books.

The kernel grows the buffers of ``lists`` and ``records`` itself when the neighbour list
overflows (a new NamedTuple replaces the old one in its typed list).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic


class ContactParams(NamedTuple):
    law_id: int             # the law's kernel id (fiberpipe.solver.laws)
    law_params: np.ndarray  # float64, the law's parameter array
    friction_on: bool       # fiber–fiber friction
    skin_m: float           # Verlet skin
    exclusion_m: float      # segments of one fiber closer than this along the fiber are not paired
    mu: float               # Coulomb coefficient
    kt_n_per_m: float       # tangential penalty stiffness
    release_s: float        # initial overlaps released linearly over this time (0: at once)
    gauss_xi: np.ndarray    # Gauss nodes on (0, 1) of the line part
    gauss_w: np.ndarray     # their weights (sum 1)
    onset_m: float          # formulation potential: penetration over which force and stiffness rise from zero


class ContactStats(NamedTuple):
    """Counters and last-step figures, each an array of one element (updated in place)."""

    n_pairs: np.ndarray       # int64, candidate pairs in the Verlet list
    n_builds: np.ndarray      # int64, neighbour-list builds so far
    n_grow: np.ndarray        # int64, times the buffers grew
    n_active: np.ndarray      # int64, pairs in contact at the last step
    overlaps_done: np.ndarray  # int64, 1: the initial overlaps have been recorded
    calls: np.ndarray         # int64, calls so far (the friction histories' time stamps)
    fn_sum_n: np.ndarray      # Σ normal force of the pairs in contact at the last step, N
    delta_max_m: np.ndarray   # largest penetration at the last step, m
    e_contact_J: np.ndarray   # stored normal contact energy at the last step, J
    e_spring_J: np.ndarray    # elastic energy of the fiber–fiber friction springs, J
    offset_max_m: np.ndarray  # largest initial-overlap offset still applied, m
    path_m: np.ndarray        # bound on the path of any node since the last build, Σ Δt max|v|, m
    delta_peak_m: np.ndarray  # largest penetration since the caller last reset it (the run's slope watch), m
    secant_peak_n_per_m: np.ndarray  # largest F_n/δ of a pair in contact since the same reset, N/m
    friction_returned_J: np.ndarray  # energy the scene's friction gave back so far (its contacts' negative dissipations), J


class Segments(NamedTuple):
    nodes: np.ndarray   # (E, 2) int64, node indices
    radius: np.ndarray  # (E,) m
    fiber: np.ndarray   # (E,) int64
    arc: np.ndarray     # (E, 2) m, arc length of the ends along the fiber


class PairList(NamedTuple):
    """A Verlet list and the histories that follow its pairs (capacity C)."""

    pairs: np.ndarray     # (C, 2) int64, segment pairs (i < j)
    keys: np.ndarray      # (C,) int64, sorted pair keys
    friction: np.ndarray  # (C, 7) tangential spring force (3), its stiffness, step of last update, s and t it acted at
    offset: np.ndarray    # (C, 1) m, initial-overlap offset


class PairRecords(NamedTuple):
    """This step's results per candidate pair (capacity C; pairs not in contact have ``fn = 0``)."""

    fn: np.ndarray      # (C,) N, normal force
    normal: np.ndarray  # (C, 3) unit normal from the second segment to the first
    s: np.ndarray       # (C,) force-weighted contact parameter on the first segment
    t: np.ndarray       # (C,) ... on the second segment
    phi: np.ndarray     # (C,) rad, crossing angle
    delta: np.ndarray   # (C,) m, largest penetration
    share: np.ndarray   # (C,) contact share (size 0: not recorded)
    fsum: np.ndarray    # (C,) N, Σ|f| of the pair's contact points (size 0: not recorded)
    gap: np.ndarray     # (C,) m, skip threshold of the pair (size 0: every pair evaluated)
    active: np.ndarray  # (C,) int64, indices of the pairs in contact (size 0: not listed)


class ContactData(NamedTuple):
    params: ContactParams
    stats: ContactStats
    segs: Segments
    x_ref: np.ndarray  # (N, 3) m, positions at the last neighbour-list build
    lists: object      # numba typed List of 2 PairList: [in use, spare]
    records: object    # numba typed List of 1 PairRecords
    fc: np.ndarray     # (N, 3) N, this step's normal contact forces
    ff: np.ndarray     # (N, 3) N, the scene's friction forces ((0, 3) without friction)


def new_stats() -> ContactStats:
    i = [np.zeros(1, np.int64) for _ in range(6)]
    f = [np.zeros(1) for _ in range(9)]
    return ContactStats(*i, *f)


@njit(cache=True)
def new_pair_list(capacity):
    """An empty :class:`PairList` of ``capacity`` pairs (the setup's and the kernel's when it grows)."""
    return PairList(np.zeros((capacity, 2), np.int64), np.zeros(capacity, np.int64), np.zeros((capacity, 7)),
                    np.zeros((capacity, 1)))


@njit(cache=True)
def new_records(capacity):
    """Empty :class:`PairRecords` of ``capacity`` pairs."""
    return PairRecords(np.zeros(capacity), np.zeros((capacity, 3)), np.zeros(capacity), np.zeros(capacity),
                       np.zeros(capacity), np.zeros(capacity), np.zeros(capacity), np.zeros(capacity),
                       np.zeros(capacity), np.zeros(capacity, np.int64))


@intrinsic
def borrowed_item(typingctx, lst, index):
    """``lst[index]`` of a numba typed list without taking a reference to the item, for a kernel
    compiled without reference counts (``_nrt=False``), where numba's ``lst[index]`` does not compile
    (it takes one). The item is valid while the list holds it: read it only until the list's entry
    is replaced. No bounds check: ``index`` must be within the list.

    It reads the list as numba's own item access does (``numba.typed.listobject``): the C list's item
    buffer (``numba_list_base_ptr``), the item's data model at ``index``, without the reference.
    """
    if not isinstance(lst, types.ListType) or not isinstance(index, types.Integer):
        return None
    item_ty = lst.item_type

    def codegen(context, builder, sig, args):
        l, idx = args
        voidptr = ir.IntType(8).as_pointer()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(voidptr, [voidptr]),
                                            "numba_list_base_ptr")
        lp = cgutils.create_struct_proxy(sig.args[0])(context, builder, value=l).data
        base = builder.bitcast(builder.call(fn, [lp]), context.get_data_type(item_ty).as_pointer())
        return context.data_model_manager[item_ty].load_from_data_pointer(builder, cgutils.gep(builder, base, idx))

    return item_ty(lst, index), codegen

"""The linear solver of every batch LM call: direct (gtsam's multifrontal Cholesky) or iterative (PCG).

gtsam's LM solves each step with a sparse Cholesky factorisation in a COLAMD ordering. On a graph with many
long-range loops (consistent groups of false loops that pass the local support test) the fill-in is catastrophic:
city10000 with 50 % random-grouped false loops costs ~1.5e11 flops per factorisation (two LM iterations: 139 s)
against ~1e8 on the clean graph (0.1 s). Preconditioned conjugate gradients with a block-Jacobi preconditioner
needs no factorisation (two LM iterations on the same graph: 0.75 s, the same cost to 5 digits) but converges
slower than the direct solve on well-conditioned clean graphs (city10000 clean to convergence: 19 s against 0.7 s).

So the choice is made per LM call from a symbolic estimate of the direct solve's cost (`fill_cost`: COLAMD
ordering and symbolic elimination of the node adjacency, no numbers): above `solver.direct_max_cost` the call
uses PCG, else the default direct solver, whose parameters are then left exactly as before (results bit-identical).

`SolverScope` (a context manager around a whole-graph solve) estimates the graph with every edge once; when that
is below the limit, so is every subgraph (fewer loops, less fill in all but pathological orderings) and no LM call
inside pays an estimate. Otherwise each call estimates its own graph (memoised on its edge set): the calls that
hold the false groups go iterative, those on the decided loops stay direct.
"""
from __future__ import annotations

import contextvars
import hashlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import gtsam
import numpy as np

from graph.params import GraphParams

_SCOPE: contextvars.ContextVar["SolverScope | _AllDirect | None"] = contextvars.ContextVar("graph_linear_scope", default=None)


# a capped estimate eliminates the ordering in slices ending at these shares of the nodes, checking the cap after
# each: few slices (each one copies the graph left), finer where the cost of a graph far above a cap passes it
FILL_SLICES = (0.25, 0.375, 0.5, 0.75, 1.0)


def fill_cost(pairs: np.ndarray, dim: int, cap: float = np.inf) -> float:
    """Estimated flops of a sparse Cholesky factorisation of the normal equations of a pose graph whose factors
    join the node pairs `pairs` ((E, 2) keys; a unary factor as (k, k)): COLAMD ordering, symbolic elimination,
    sum over the eliminated nodes of tangent_dim^3 x (column count in nodes)^2.

    With a finite `cap` the elimination stops once the nodes eliminated so far cost more than `cap`, and that
    partial sum (a lower bound, > cap) is returned: a node's column count depends only on the graph and the nodes
    eliminated before it, so the sum over a prefix of the ordering is exact for those nodes, and the symbolic work
    of the slices not reached is saved (w10000 + 50 % random-grouped false loops, 1.7e12: 2.1 s for the whole
    elimination, the first 3e10 within its first third of the nodes, ~0.1 s)."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if not len(pairs):
        return 0.0
    # distinct pairs in lexicographic order, as one integer code each (np.unique over rows is slow on 10^5 pairs)
    p = np.sort(pairs, axis=1)
    width = int(p.max()) + 1
    codes = np.unique(p[:, 0] * width + p[:, 1])
    sfg = gtsam.SymbolicFactorGraph()
    for i, j in zip((codes // width).tolist(), (codes % width).tolist()):
        if i == j:
            sfg.push_factor(i)
        else:
            sfg.push_factor(i, j)
    d3 = (3.0 if dim == 2 else 6.0) ** 3
    ordering = gtsam.Ordering.ColamdSymbolicFactorGraph(sfg)
    if not np.isfinite(cap):
        return d3 * _count_cost(sfg.eliminateSequential(ordering))
    keys = [ordering.at(i) for i in range(ordering.size())]
    total, lo = 0.0, 0
    for share in FILL_SLICES:
        hi = len(keys) if share >= 1.0 else int(share * len(keys))
        part = gtsam.Ordering()
        for k in keys[lo:hi]:
            part.push_back(k)
        lo = hi
        net, sfg = sfg.eliminatePartialSequential(part)
        total += d3 * _count_cost(net)
        if total > cap:
            break
    return total


def _count_cost(net) -> float:
    """Sum over a symbolic Bayes net's conditionals of (column count in nodes)^2."""
    counts = np.fromiter((net.at(k).nrParents() + 1 for k in range(net.size())), float, net.size())
    return float(np.sum(counts ** 2))


def graph_pairs(graph: gtsam.NonlinearFactorGraph) -> np.ndarray:
    """(E, 2) key pairs of a graph's unary and binary factors (unary: (k, k))."""
    out = np.empty((graph.size(), 2), np.int64)
    n = 0
    for i in range(graph.size()):
        f = graph.at(i)
        if f is None:
            continue
        keys = f.keys()
        if len(keys) == 1:
            out[n] = (keys[0], keys[0])
        elif len(keys) == 2:
            out[n] = keys
        else:
            continue
        n += 1
    return out[:n]


class _AllDirect:
    """A scope in which every call is direct (see `narrow`)."""

    all_direct = True
    iterative_calls = 0

    @staticmethod
    def iterative(graph: gtsam.NonlinearFactorGraph) -> bool:
        return False


_DIRECT = _AllDirect()


class SolverScope:
    """The solver choice for the LM calls of one whole-graph solve (see the module doc)."""

    KNOWN = 8        # edge sets remembered on each side of the limit (subset / superset tests per call)

    def __init__(self, pairs: np.ndarray | Callable[[], np.ndarray], dim: int, params: GraphParams):
        self.dim = dim
        self.limit = float(params.solver.direct_max_cost)
        self.params = params
        self._memo: dict[bytes, bool] = {}
        self._cheap: list[tuple[int, np.ndarray]] = []    # (key width, sorted pair codes) estimated under the limit
        self._dear: list[tuple[int, np.ndarray]] = []     # ... and above it
        self.iterative_calls = 0
        # the whole graph under the limit: every call direct, no estimate per call. Estimated on first need
        # (`all_direct`), unless a `narrow` block's subgraph, estimated first and above the limit, settles it: the
        # whole graph is then above too (w10000 at 50 % random: 1.6e12 estimated flops, 1-2 s of symbolic
        # elimination, the candidates' 3e11 settle it in a third of that). Once made, the whole graph's estimate is
        # remembered like any other: a later call on the same edges (the candidates, when every loop is supported)
        # is settled by it (w10000 at 50 % random-grouped: 2.4 s an elimination)
        self._pairs = pairs
        self._all_direct: bool | None = True if not np.isfinite(self.limit) else None

    @property
    def all_direct(self) -> bool:
        """Whether the whole graph is estimated under the limit (every call direct)."""
        if self._all_direct is None:
            self._all_direct = not self._estimate(self._whole())
            self._pairs = None
        return self._all_direct

    def narrow_dear(self, pairs: Callable[[], np.ndarray]) -> bool | None:
        """For `narrow`: None when the whole graph is under the limit (every call direct), else whether the subgraph
        `pairs()` is above it. While the whole graph is not estimated yet a proper subgraph goes first, and one above
        the limit settles the whole graph as above too (fill-in only grows with edges)."""
        if self._all_direct is None:
            sub = np.asarray(pairs())
            if len(sub) < len(self._whole()) and self._estimate(sub):
                self._all_direct = False
                return True
            return None if self.all_direct else self._estimate(sub)
        return None if self._all_direct else self._estimate(np.asarray(pairs()))

    def _whole(self) -> np.ndarray:
        if callable(self._pairs):
            self._pairs = np.asarray(self._pairs())
        return self._pairs

    def iterative(self, graph: gtsam.NonlinearFactorGraph) -> bool:
        """Whether an LM call on `graph` should use PCG."""
        if self.all_direct:
            return False
        pairs = graph_pairs(graph)
        key = hashlib.blake2b(np.ascontiguousarray(pairs).tobytes(), digest_size=16).digest()
        hit = self._memo.get(key)
        if hit is None:
            hit = self._memo[key] = self._estimate(pairs)
        return hit

    def _estimate(self, pairs: np.ndarray) -> bool:
        # fill-in only grows with edges: a subgraph of a graph under the limit is under it, a supergraph of one
        # above is above (exact for a fixed ordering; COLAMD re-orders, a small difference near the limit). The
        # GNC steps of one solve drop and re-weight the same loops, so most calls are settled without an
        # elimination (0.1-0.4 s each on 10^4 nodes with the false groups in)
        p = np.sort(pairs, axis=1)
        width = int(p.max()) + 1 if len(p) else 1
        codes = np.unique(p[:, 0] * width + p[:, 1])
        for known_width, known in self._cheap:
            if known_width == width and np.isin(codes, known, assume_unique=True).all():
                return False
        for known_width, known in self._dear:
            if known_width == width and np.isin(known, codes, assume_unique=True).all():
                return True
        dear = fill_cost(pairs, self.dim, self.limit) > self.limit
        (self._dear if dear else self._cheap).append((width, codes))
        del (self._dear if dear else self._cheap)[:-self.KNOWN]
        return dear


@contextmanager
def solver_scope(pairs: np.ndarray | Callable[[], np.ndarray], dim: int, params: GraphParams
                 ) -> Iterator["SolverScope | _AllDirect"]:
    """Every LM call made through `configure` inside the block chooses its linear solver from `pairs`' scope.
    Inside a scope already open (the robust solve behind a batch strategy's solve) the outer one holds."""
    outer = _SCOPE.get()
    if outer is not None:
        yield outer
        return
    scope = SolverScope(pairs, dim, params)
    token = _SCOPE.set(scope)
    try:
        yield scope
    finally:
        _SCOPE.reset(token)


@contextmanager
def narrow(pairs: Callable[[], np.ndarray]) -> Iterator[None]:
    """Inside the block every LM call's graph is a subgraph of the edges `pairs()` (a caller's promise): when those
    are under the limit every call is direct without an estimate of its own (the GNC steps of a solve whose false
    loops are all outside its candidates: city10000 at 50 % random). No-op outside a scope or when the scope is
    all direct; `pairs` is only called when needed."""
    outer = _SCOPE.get()
    dear = outer.narrow_dear(pairs) if isinstance(outer, SolverScope) else None
    if dear is None:
        yield
        return
    token = _SCOPE.set(_DIRECT if not dear else outer)
    try:
        yield
    finally:
        _SCOPE.reset(token)


@contextmanager
def direct() -> Iterator[None]:
    """Inside the block every LM call is direct: for graphs known to be small (a reduced problem of a few hundred
    poses, graph.reduced), which need no estimate and must not take a place among the scope's remembered edge sets."""
    token = _SCOPE.set(_DIRECT)
    try:
        yield
    finally:
        _SCOPE.reset(token)


class _AllIterative:
    """A scope in which every call is iterative (see `iterative_above`)."""

    all_direct = False

    def __init__(self, outer: "SolverScope"):
        self.params = outer.params
        self.iterative_calls = 0

    @staticmethod
    def iterative(graph: gtsam.NonlinearFactorGraph) -> bool:
        return True


def above(pairs: Callable[[], np.ndarray], limit: float) -> bool:
    """Whether a graph with the edges `pairs()` is estimated above `limit` in the current scope (`iterative_above`
    makes its calls iterative then); False outside a scope or in an all-direct one."""
    outer = _SCOPE.get()
    return not (outer is None or outer.all_direct or fill_cost(np.asarray(pairs()), outer.dim, limit) <= limit)


@contextmanager
def iterative_above(pairs: Callable[[], np.ndarray], limit: float, dear: bool | None = None) -> Iterator[None]:
    """Inside the block every LM call's graph is a subgraph of the edges `pairs()` (as with `narrow`), and every
    call is iterative when those are estimated above `limit` (else `narrow`'s choice). For solves of a few warm
    iterations each (a GNC's steps), where PCG's slower convergence to a tight tolerance costs little. No-op outside
    a scope or in an all-direct one. `dear`: `above(pairs, limit)` when the caller has it already."""
    outer = _SCOPE.get()
    if not (above(pairs, limit) if dear is None else dear):
        with narrow(pairs):
            yield
        return
    token = _SCOPE.set(_AllIterative(outer))
    try:
        yield
    finally:
        _SCOPE.reset(token)


def costly(pairs: Callable[[], np.ndarray]) -> bool:
    """Whether an LM call on a graph with the edges `pairs()` would go iterative in the current scope (its direct
    factorisation estimated above `solver.direct_max_cost`); False outside a scope or in an all-direct one."""
    scope = _SCOPE.get()
    if scope is None or scope.all_direct:
        return False
    return scope._estimate(np.asarray(pairs()))


def pcg_parameters(params: GraphParams) -> gtsam.PCGSolverParameters:
    """PCG with a block-Jacobi preconditioner (one 3x3 / 6x6 block per pose)."""
    pcg = gtsam.PCGSolverParameters()
    pcg.preconditioner = gtsam.BlockJacobiPreconditionerParameters()
    pcg.maxIterations = params.solver.pcg_max_iterations
    pcg.epsilon_rel = params.solver.pcg_relative_tol
    pcg.epsilon_abs = params.solver.pcg_relative_tol
    return pcg


def configure(lm: gtsam.LevenbergMarquardtParams, graph: gtsam.NonlinearFactorGraph | None
              ) -> gtsam.LevenbergMarquardtParams:
    """Switch `lm` to PCG when the current scope says the direct solve of `graph` is too costly; outside a scope,
    or without a graph, `lm` is left as it is (the direct solver)."""
    scope = _SCOPE.get()
    if scope is None or graph is None or not scope.iterative(graph):
        return lm
    scope.iterative_calls += 1
    lm.setLinearSolverType("ITERATIVE")
    lm.setIterativeParams(pcg_parameters(scope.params))
    return lm


def run_lm(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, max_iterations: int, relative_tol: float,
           absolute_tol: float) -> tuple[gtsam.Values, int]:
    """gtsam's LM from `values` to the given tolerances, its linear solver chosen for `graph` (`configure`); returns
    (values, iterations). The one place every batch LM call of the back end is made."""
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(max_iterations)
    p.setRelativeErrorTol(relative_tol)
    p.setAbsoluteErrorTol(absolute_tol)
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, configure(p, graph))
    return opt.optimize(), int(opt.iterations())

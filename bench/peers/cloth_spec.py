"""The benchmark cloth, defined once for every peer framework.

Must match the Rust benchmark exactly (SI units):

* 64 x 64 nodes on a 1 m x 1 m square, horizontal at rest:
  node (i, j) at x = i/63, y = 0, z = j/63, index k = j*64 + i
  (i = column, j = row).
* Lumped mass, areal density 0.2 kg/m^2 times the node's Voronoi cell
  (interior h^2, edge h^2/2, corner h^2/4, h = 1/63).
* Springs (rest length = rest distance), force on a from spring a-b
  (Sung 2018 eq. 1): d = x_b - x_a, L = |d|, u = d/L,
  F_a = K (L - L0) u + C ((v_b - v_a) . u) u,  F_b = -F_a.
    structural (i,j)-(i+1,j), (i,j)-(i,j+1)   K=400 N/m C=0.04 N s/m
    shear      (i,j)-(i+1,j+1), (i+1,j)-(i,j+1) K=60  C=0.006
    bend       (i,j)-(i+2,j), (i,j)-(i,j+2)   K=8   C=0.0008
* Global drag F = -1.0 * m * v, gravity (0, -9.81, 0).
* Pinned: nodes (0,0) and (63,0) (velocity zero, position fixed).
* dt = 1e-4 s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

N_SIDE = 64
N_NODES = N_SIDE * N_SIDE
SIZE = 1.0  # m
H = SIZE / (N_SIDE - 1)
AREAL_DENSITY = 0.2  # kg/m^2
DRAG = 1.0  # 1/s
GRAVITY = (0.0, -9.81, 0.0)  # m/s^2
DT = 1e-4  # s

K_STRUCT, C_STRUCT = 400.0, 0.04
K_SHEAR, C_SHEAR = 60.0, 0.006
K_BEND, C_BEND = 8.0, 0.0008


def node(i: int, j: int) -> int:
    """Index of node (column i, row j)."""
    return j * N_SIDE + i


PINNED = (node(0, 0), node(N_SIDE - 1, 0))
PROBE = node(32, N_SIDE - 1)  # bottom-middle node used for the sanity print

# Spring families: (offset of a from (i,j), offset of b from (i,j), K, C).
# The family order (and the row-major (j, i) order inside each family) fixes
# the spring order for every framework.
FAMILIES = (
    ("structural", (0, 0), (1, 0), K_STRUCT, C_STRUCT),
    ("structural", (0, 0), (0, 1), K_STRUCT, C_STRUCT),
    ("shear", (0, 0), (1, 1), K_SHEAR, C_SHEAR),
    ("shear", (1, 0), (0, 1), K_SHEAR, C_SHEAR),
    ("bend", (0, 0), (2, 0), K_BEND, C_BEND),
    ("bend", (0, 0), (0, 2), K_BEND, C_BEND),
)


@dataclass(frozen=True)
class Cloth:
    x0: np.ndarray  # (N, 3) float64 rest positions
    mass: np.ndarray  # (N,) float64
    free: np.ndarray  # (N,) float64, 0 for pinned nodes, 1 otherwise
    a: np.ndarray  # (S,) int32 first node of each spring
    b: np.ndarray  # (S,) int32 second node
    rest: np.ndarray  # (S,) float64 rest lengths
    k: np.ndarray  # (S,) float64 stiffness
    c: np.ndarray  # (S,) float64 damping

    @property
    def n_springs(self) -> int:
        return len(self.a)


def build() -> Cloth:
    jj, ii = np.meshgrid(np.arange(N_SIDE), np.arange(N_SIDE), indexing="ij")
    x0 = np.zeros((N_NODES, 3))
    x0[:, 0] = (ii / (N_SIDE - 1)).ravel()
    x0[:, 2] = (jj / (N_SIDE - 1)).ravel()

    # Voronoi cell area: h (or h/2 on a border) in each direction.
    wi = np.where((ii == 0) | (ii == N_SIDE - 1), 0.5, 1.0)
    wj = np.where((jj == 0) | (jj == N_SIDE - 1), 0.5, 1.0)
    mass = (AREAL_DENSITY * H * H * wi * wj).ravel()

    free = np.ones(N_NODES)
    free[list(PINNED)] = 0.0

    a_l, b_l, k_l, c_l = [], [], [], []
    for _name, (ai, aj), (bi, bj), k, c in FAMILIES:
        span_i = max(ai, bi)
        span_j = max(aj, bj)
        j, i = np.meshgrid(np.arange(N_SIDE - span_j), np.arange(N_SIDE - span_i), indexing="ij")
        a_l.append(node(i + ai, j + aj).ravel())
        b_l.append(node(i + bi, j + bj).ravel())
        k_l.append(np.full(a_l[-1].size, k))
        c_l.append(np.full(a_l[-1].size, c))
    a = np.concatenate(a_l).astype(np.int32)
    b = np.concatenate(b_l).astype(np.int32)
    rest = np.linalg.norm(x0[b] - x0[a], axis=1)
    cloth = Cloth(x0, mass, free, a, b, rest, np.concatenate(k_l), np.concatenate(c_l))
    assert cloth.n_springs == 8064 + 7938 + 7936 == 23938
    assert abs(mass.sum() - AREAL_DENSITY * SIZE * SIZE) < 1e-12
    return cloth


def sanity(x: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """(y of the bottom-middle node, max |v| over all nodes)."""
    return float(x[PROBE, 1]), float(np.sqrt((np.asarray(v, np.float64) ** 2).sum(axis=1)).max())

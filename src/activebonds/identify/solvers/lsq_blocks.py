"""A linear least-squares problem that falls apart into blocks: groups of unknowns whose
columns share no row (and no product constraint) with another group's. The cost is a sum over
the blocks and the constraints stay within them, so each block's optimum is the whole
problem's there: a model whose markers no force joins (a periodic force per marker) is one
small problem per marker, not one of every unknown at once."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components


def blocks(columns: np.ndarray, pairs) -> list[tuple[np.ndarray, np.ndarray]]:
    """(rows, unknowns) of each block of ``columns`` [R, K] (``pairs``: the product
    constraints ``(k, p, lo, hi)``, which join ``k`` and ``p``), rows where none of the
    block's columns is non-zero left out; one block (every row, every unknown) where the
    problem does not fall apart."""
    n_rows, k = columns.shape
    whole = [(np.arange(n_rows), np.arange(k))]
    if k < 2:
        return whole
    touched = csr_matrix(columns != 0)
    links = (touched.T @ touched).tocoo()
    if pairs:
        a, b = np.array([[p[0], p[1]] for p in pairs]).T
        links = coo_matrix(
            (np.ones(len(a) + links.nnz), (np.r_[links.row, a], np.r_[links.col, b])), (k, k)
        )
    count, label = connected_components(links, directed=False)
    if count == 1:
        return whole
    # each row's block: the block of any non-zero column in it (-1: none)
    row_block = np.full(n_rows, -1)
    coo = touched.tocoo()
    row_block[coo.row] = label[coo.col]
    return [(np.flatnonzero(row_block == b), np.flatnonzero(label == b)) for b in range(count)]

"""Graph algorithms of the sparse engine's block-triangular order (Dulmage-Mendelsohn): a
perfect matching of rows to columns, and the strongly connected components of the resulting
dependency graph."""
from __future__ import annotations


def _matching(row_cols: list, n: int):
    """Return a perfect matching row -> column of a bipartite pattern (Kuhn), or None."""
    col_row = [-1] * n

    def augment(r, seen):
        for c in row_cols[r]:
            if not seen[c]:
                seen[c] = True
                if col_row[c] < 0 or augment(col_row[c], seen):
                    col_row[c] = r
                    return True
        return False

    for r in range(len(row_cols)):
        if not augment(r, [False] * n):
            return None
    match = [0] * len(row_cols)
    for c, r in enumerate(col_row):
        match[r] = c
    return match


def _components(succ: list) -> list:
    """Return the strongly connected components of a graph (Tarjan), each after its predecessors."""
    n = len(succ)
    index, low, on, stack, out = [None] * n, [0] * n, [False] * n, [], []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on[v] = True
        for w in succ[v]:
            if index[w] is None:
                visit(w)
                low[v] = min(low[v], low[w])
            elif on[w]:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on[w] = False
                comp.append(w)
                if w == v:
                    break
            out.append(comp)

    for v in range(n):
        if index[v] is None:
            visit(v)
    return out[::-1]  # Tarjan emits sinks first: reversed, every component follows its sources

#pragma once
// Distance-2 column colouring of a sparsity pattern, for compressed Jacobians and per-output
// Hessian recovery (docs/sparse-derivatives.md). Implemented with ColPack; this header keeps
// ColPack's headers (which open `using namespace std;`) out of every other file.

#include <vector>

namespace moreau::internal {

// Colours the columns of a pattern given row by row (row r holds the columns
// column_index[row_start[r] .. row_start[r + 1]), each at most once) so that two columns sharing
// a row have different colours: a partial distance-2 colouring of the bipartite row-column graph
// (Gebremedhin, Manne & Pothen, SIAM Review 47(4), 2005), with ColPack's smallest-last ordering
// and its sequential greedy colouring (deterministic). Returns the colour of every column:
// 0 .. *num_colors - 1 for columns in some row (numbered by first use in increasing column
// order), -1 for columns in no row. Aborts (MOREAU_ASSERT) if the colouring ColPack returns is
// not valid.
std::vector<int> ColorColumnsDistanceTwo(int num_columns, const std::vector<int>& row_start,
                                         const std::vector<int>& column_index, int* num_colors);

}  // namespace moreau::internal

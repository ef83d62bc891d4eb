// Sparse exact derivatives (docs/sparse-derivatives.md): sparsity detection from a traced
// evaluation, distance-2 colourings per row subset, compressed forward mode with Dual1 and
// Dual2, and recovery straight into a fixed compressed-column pattern.
#include "sparse_derivatives.hpp"

#include <algorithm>
#include <cstring>
#include <deque>
#include <limits>
#include <utility>

#include "column_coloring.hpp"
#include "thread_pool.hpp"

namespace moreau::internal {

namespace {

constexpr int kChunk = Dual1::kCapacity;  // directions per Dual1/Dual2 level and evaluation

using Kind = SparsityTape::Kind;

// Jacobian and second-derivative patterns of the outputs `output_nodes` of a traced evaluation.
// The Jacobian pattern of an output is the set of inputs reachable from its node; its
// second-derivative pattern is the union, over the nonlinear nodes reachable from it, of the
// pairs of inputs that node's operation couples (Walther 2008, "nonlinear interaction
// domains"). Cost: the nodes reachable from each output, plus one dependency set per operand of
// a nonlinear node (memoized), plus the pairs generated.
void AnalyzeTape(const SparsityTape& tape, const std::vector<int>& output_nodes, int num_inputs,
                 SparsityPattern* pattern) {
  const std::size_t num_nodes = tape.nodes.size();
  std::vector<int> reach_mark(num_nodes, -1), dep_mark(num_nodes, -1);
  int dep_stamp = 0;
  std::vector<int> memo_index(num_nodes, -1);
  std::deque<std::vector<int>> memo;  // deque: references stay valid as it grows
  std::vector<int> reach_stack, dep_stack, inputs, nonlinear;
  std::vector<std::pair<int, int>> pairs;

  // D(node): the sorted inputs on which `node` depends.
  auto dependencies = [&](int node) -> const std::vector<int>& {
    int& index = memo_index[static_cast<std::size_t>(node)];
    if (index >= 0) return memo[static_cast<std::size_t>(index)];
    std::vector<int> result;
    ++dep_stamp;
    dep_stack.assign(1, node);
    while (!dep_stack.empty()) {
      const int v = dep_stack.back();
      dep_stack.pop_back();
      if (dep_mark[static_cast<std::size_t>(v)] == dep_stamp) continue;
      dep_mark[static_cast<std::size_t>(v)] = dep_stamp;
      if (v < num_inputs) {
        result.push_back(v);
        continue;
      }
      const SparsityTape::Node& n = tape.nodes[static_cast<std::size_t>(v)];
      if (n.a >= 0) dep_stack.push_back(n.a);
      if (n.b >= 0) dep_stack.push_back(n.b);
    }
    std::sort(result.begin(), result.end());
    index = static_cast<int>(memo.size());
    memo.push_back(std::move(result));
    return memo.back();
  };
  auto add_product = [&pairs](const std::vector<int>& a, const std::vector<int>& b) {
    for (int i : a) {
      for (int j : b) pairs.emplace_back(std::min(i, j), std::max(i, j));
    }
  };
  auto add_square = [&pairs](const std::vector<int>& a) {
    for (std::size_t i = 0; i < a.size(); ++i) {
      for (std::size_t j = i; j < a.size(); ++j) pairs.emplace_back(a[i], a[j]);
    }
  };

  const int num_outputs = static_cast<int>(output_nodes.size());
  pattern->jac_start.assign(1, 0);
  pattern->hess_start.assign(1, 0);
  pattern->jac_inputs.clear();
  pattern->hess_first.clear();
  pattern->hess_second.clear();
  std::vector<int> merged;
  for (int k = 0; k < num_outputs; ++k) {
    inputs.clear();
    nonlinear.clear();
    pairs.clear();
    const int root = output_nodes[static_cast<std::size_t>(k)];
    if (root >= 0) reach_stack.assign(1, root);
    while (!reach_stack.empty()) {
      const int v = reach_stack.back();
      reach_stack.pop_back();
      if (reach_mark[static_cast<std::size_t>(v)] == k) continue;
      reach_mark[static_cast<std::size_t>(v)] = k;
      if (v < num_inputs) {
        inputs.push_back(v);
        continue;
      }
      const SparsityTape::Node& n = tape.nodes[static_cast<std::size_t>(v)];
      if (n.kind != Kind::kLinear) nonlinear.push_back(v);
      if (n.a >= 0) reach_stack.push_back(n.a);
      if (n.b >= 0) reach_stack.push_back(n.b);
    }
    std::sort(inputs.begin(), inputs.end());
    pattern->jac_inputs.insert(pattern->jac_inputs.end(), inputs.begin(), inputs.end());
    pattern->jac_start.push_back(static_cast<int>(pattern->jac_inputs.size()));

    for (int v : nonlinear) {
      const SparsityTape::Node& n = tape.nodes[static_cast<std::size_t>(v)];
      switch (n.kind) {
        case Kind::kProduct:  // d2(ab) = da db + db da
          add_product(dependencies(n.a), dependencies(n.b));
          break;
        case Kind::kQuotient: {  // d2(a/b) couples a with b and b with itself
          const std::vector<int>& b = dependencies(n.b);
          if (n.a >= 0) add_product(dependencies(n.a), b);
          add_square(b);
          break;
        }
        case Kind::kNonlinear: {
          if (n.b < 0) {
            add_square(dependencies(n.a));
          } else {
            const std::vector<int>& a = dependencies(n.a);
            const std::vector<int>& b = dependencies(n.b);
            merged.clear();
            std::set_union(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(merged));
            add_square(merged);
          }
          break;
        }
        case Kind::kInput:
        case Kind::kLinear:
          break;
      }
    }
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    for (const auto& [i, j] : pairs) {
      pattern->hess_first.push_back(i);
      pattern->hess_second.push_back(j);
    }
    pattern->hess_start.push_back(static_cast<int>(pattern->hess_first.size()));
  }
}

// Column of each input for `wrt` (x | u | t | p with unselected blocks removed), or -1.
std::vector<int> ColumnsOfInputs(const SparsityPattern& pattern, Wrt wrt, int* num_columns) {
  std::vector<int> column(static_cast<std::size_t>(pattern.num_inputs), -1);
  int next = 0;
  int input = 0;
  auto block = [&](int size, bool selected) {
    for (int i = 0; i < size; ++i, ++input) {
      column[static_cast<std::size_t>(input)] = selected ? next++ : -1;
    }
  };
  block(pattern.nx, wrt.x);
  block(pattern.nu, wrt.u);
  block(1, wrt.t);
  block(pattern.np, wrt.p);
  *num_columns = next;
  return column;
}

// The rows of a call: all outputs, or the caller's subset (checked once, when a plan is made).
std::vector<int> SelectedRows(const TypedFunction& function, const std::vector<int>* rows) {
  const int m = function.num_outputs();
  if (rows == nullptr) {
    std::vector<int> all(static_cast<std::size_t>(m));
    for (int k = 0; k < m; ++k) all[static_cast<std::size_t>(k)] = k;
    return all;
  }
  for (std::size_t r = 0; r < rows->size(); ++r) {
    const int k = (*rows)[r];
    RequireArgument(k >= 0 && k < m, "function '", function.name(), "': row ", k,
                    " of the sparse derivative's row subset is not an output (", m, " outputs)");
    RequireArgument(r == 0 || (*rows)[r - 1] < k, "function '", function.name(),
                    "': the row subset of a sparse derivative must be sorted and unique, got ",
                    (*rows)[r - 1], " before ", k);
  }
  return *rows;
}

// A compressed-column pattern with zero values from per-column sorted row lists.
SparseMatrix PatternMatrix(int rows, int cols, const std::vector<int>& column_start,
                           const std::vector<int>& row_index) {
  SparseMatrix matrix(rows, cols);
  matrix.resizeNonZeros(static_cast<Eigen::Index>(row_index.size()));
  std::copy(column_start.begin(), column_start.end(), matrix.outerIndexPtr());
  std::copy(row_index.begin(), row_index.end(), matrix.innerIndexPtr());
  std::fill(matrix.valuePtr(), matrix.valuePtr() + row_index.size(), 0.0);
  MOREAU_ASSERT(matrix.isCompressed(), "pattern matrix must be compressed");
  return matrix;
}

// Gives `target` the pattern of `pattern` unless it already has it (then only its values are
// overwritten by the caller: no allocation in steady state).
void AdoptPattern(const SparseMatrix& pattern, SparseMatrix* target) {
  const bool same =
      target->rows() == pattern.rows() && target->cols() == pattern.cols() &&
      target->isCompressed() && target->nonZeros() == pattern.nonZeros() &&
      std::equal(pattern.outerIndexPtr(), pattern.outerIndexPtr() + pattern.cols() + 1,
                 target->outerIndexPtr()) &&
      std::equal(pattern.innerIndexPtr(), pattern.innerIndexPtr() + pattern.nonZeros(),
                 target->innerIndexPtr());
  if (!same) *target = pattern;
}

// Adds w d^2 g / (d outer d inner) from a Dual2 evaluation (outer level: direction `outer`,
// inner level: `inner`; directions beyond the ones a value carries are zero) at a Hessian
// entry and at its mirror (once on the diagonal, where ij == ji).
void AddSecondDerivative(const Dual2& g, int outer, int inner, double w, int ij, int ji,
                         double* values) {
  double second = 0.0;
  if (outer < g.size()) {
    const Dual1& row = g.d(outer);
    if (inner < row.size()) second = row.d(inner);
  }
  values[ij] += w * second;
  if (ji != ij) values[ji] += w * second;
}

}  // namespace

FunctionStructure AnalyzeStructure(const SparsityPattern& pattern) {
  FunctionStructure structure;
  structure.nx = pattern.nx;
  structure.nu = pattern.nu;
  structure.np = pattern.np;
  structure.point_dependent = pattern.point_dependent;
  structure.piecewise = pattern.piecewise;
  auto block = [&pattern](int input) {
    if (input < pattern.nx) return 0;
    if (input < pattern.nx + pattern.nu) return 1;
    return input == pattern.nx + pattern.nu ? 2 : 3;
  };
  for (std::size_t e = 0; e < pattern.hess_first.size(); ++e) {
    const int a = block(pattern.hess_first[e]), b = block(pattern.hess_second[e]);
    structure.couples[a][b] = structure.couples[b][a] = true;
  }
  bool depends[4] = {};
  for (const int input : pattern.jac_inputs) depends[block(input)] = true;
  for (unsigned bits = 0; bits < 16 && !structure.point_dependent; ++bits) {
    bool zero = true;
    for (int a = 0; a < 4; ++a) {
      for (int b = 0; b < 4; ++b) {
        const bool selected = ((bits >> a) & 1u) != 0 && ((bits >> b) & 1u) != 0;
        zero = zero && !(selected && structure.couples[a][b]);
      }
    }
    if (zero) structure.hessian_zero |= 1u << bits;
    bool independent = true;
    for (int a = 0; a < 4; ++a)
      independent = independent && !(((bits >> a) & 1u) != 0 && depends[a]);
    if (independent) structure.jacobian_zero |= 1u << bits;
  }
  return structure;
}

SparsityPattern DetectSparsity(TypedFunction* function, const ConstVectorRef& x,
                               const ConstVectorRef& u, double t, const ConstVectorRef& p) {
  SparsityPattern pattern;
  pattern.nx = static_cast<int>(x.size());
  pattern.nu = static_cast<int>(u.size());
  pattern.np = static_cast<int>(p.size());
  pattern.num_inputs = pattern.nx + pattern.nu + 1 + pattern.np;
  SparsityTape tape;
  tape.nodes.reserve(static_cast<std::size_t>(pattern.num_inputs) * 4);
  std::vector<SparsityTracer> inputs;
  inputs.reserve(static_cast<std::size_t>(pattern.num_inputs));
  auto add = [&](double value) {
    const int node = tape.Record(Kind::kInput, -1, -1);
    inputs.emplace_back(value, &tape, node);
  };
  for (Eigen::Index i = 0; i < x.size(); ++i) add(x[i]);
  for (Eigen::Index i = 0; i < u.size(); ++i) add(u[i]);
  add(t);
  for (Eigen::Index i = 0; i < p.size(); ++i) add(p[i]);
  std::vector<SparsityTracer> outputs(static_cast<std::size_t>(function->num_outputs()),
                                      SparsityTracer(0.0));
  const SparsityTracer* base = inputs.data();
  function->Call(base, pattern.nx, base + pattern.nx, pattern.nu, base[pattern.nx + pattern.nu],
                 base + pattern.nx + pattern.nu + 1, pattern.np, outputs.data());
  std::vector<int> output_nodes(outputs.size());
  for (std::size_t k = 0; k < outputs.size(); ++k) {
    MOREAU_ASSERT(!outputs[k].traced() || outputs[k].tape() == &tape,
                  "an output of the traced evaluation belongs to another evaluation");
    output_nodes[k] = outputs[k].node();
  }
  pattern.point_dependent = tape.value_dependent;
  pattern.piecewise = tape.piecewise;
  AnalyzeTape(tape, output_nodes, pattern.num_inputs, &pattern);
  return pattern;
}

std::shared_ptr<const AnalyzedPattern> FunctionAnalysis::Find(TypedFunction* function,
                                                              const ConstVectorRef& x,
                                                              const ConstVectorRef& u, double t,
                                                              const ConstVectorRef& p,
                                                              bool* detected) {
  const int nx = static_cast<int>(x.size()), nu = static_cast<int>(u.size()),
            np = static_cast<int>(p.size());
  const std::lock_guard<std::mutex> lock(mutex_);
  *detected = false;
  for (const auto& entry : entries_) {
    if (entry->pattern.SameSizes(nx, nu, np)) return entry;
  }
  auto entry = std::make_shared<AnalyzedPattern>();
  entry->pattern = DetectSparsity(function, x, u, t, p);
  entry->structure = AnalyzeStructure(entry->pattern);
  entries_.push_back(entry);
  *detected = true;
  return entry;
}

bool MergePattern(const SparsityPattern& other, SparsityPattern* into) {
  MOREAU_ASSERT(other.SameSizes(into->nx, into->nu, into->np), "merging patterns of other sizes");
  const int m = static_cast<int>(into->jac_start.size()) - 1;
  bool grew = false;
  std::vector<int> jac_start{0}, jac_inputs, hess_start{0}, hess_first, hess_second;
  for (int k = 0; k < m; ++k) {
    const auto k0 = static_cast<std::size_t>(k), k1 = k0 + 1;
    const auto a0 = into->jac_inputs.begin() + into->jac_start[k0];
    const auto a1 = into->jac_inputs.begin() + into->jac_start[k1];
    const auto b0 = other.jac_inputs.begin() + other.jac_start[k0];
    const auto b1 = other.jac_inputs.begin() + other.jac_start[k1];
    const std::size_t before = jac_inputs.size();
    std::set_union(a0, a1, b0, b1, std::back_inserter(jac_inputs));
    grew = grew || static_cast<long>(jac_inputs.size() - before) != (a1 - a0);
    jac_start.push_back(static_cast<int>(jac_inputs.size()));

    // Pairs, merged in lexicographic order.
    int a = into->hess_start[k0], b = other.hess_start[k0];
    const int a_end = into->hess_start[k1], b_end = other.hess_start[k1];
    auto key = [](const std::vector<int>& first, const std::vector<int>& second, int e) {
      return std::make_pair(first[static_cast<std::size_t>(e)],
                            second[static_cast<std::size_t>(e)]);
    };
    while (a < a_end || b < b_end) {
      std::pair<int, int> next;
      if (b >= b_end || (a < a_end && key(into->hess_first, into->hess_second, a) <=
                                          key(other.hess_first, other.hess_second, b))) {
        next = key(into->hess_first, into->hess_second, a);
        if (b < b_end && key(other.hess_first, other.hess_second, b) == next) ++b;
        ++a;
      } else {
        next = key(other.hess_first, other.hess_second, b++);
        grew = true;
      }
      hess_first.push_back(next.first);
      hess_second.push_back(next.second);
    }
    hess_start.push_back(static_cast<int>(hess_first.size()));
  }
  if (grew) {
    into->jac_start = std::move(jac_start);
    into->jac_inputs = std::move(jac_inputs);
    into->hess_start = std::move(hess_start);
    into->hess_first = std::move(hess_first);
    into->hess_second = std::move(hess_second);
  }
  into->point_dependent = into->point_dependent || other.point_dependent;
  into->piecewise = into->piecewise || other.piecewise;
  return grew;
}

// ---- plans --------------------------------------------------------------------------------

// Everything about SparseJacobian for one (wrt, rows) that does not depend on the point.
struct SparseDerivatives::JacobianPlan {
  unsigned wrt_bits = 0;
  bool all_rows = true;
  std::vector<int> rows;
  std::uint64_t last_use = 0;

  SparseMatrix pattern;  // num_outputs x columns, zero values
  int num_colors = 0;
  int num_passes = 0;  // ceil(num_colors / kChunk) Dual1 evaluations
  // Inputs seeded in pass q: seeded_input[seeded_start[q] .. seeded_start[q + 1]), with their
  // direction (colour - q kChunk).
  std::vector<int> seeded_start, seeded_input, seeded_direction;
  // Entries recovered in pass q: [entry_start[q], entry_start[q + 1]): value position in the
  // pattern, output, direction.
  std::vector<int> entry_start, entry_position, entry_output, entry_direction;
  // Functions made of blocks (no colouring): the blocks holding a selected row; per block b
  // (index into `blocks`) its seeded inputs block_input[block_input_start[b] ..] (sorted; the
  // local direction of an input is its index there), its selected rows block_row[
  // block_row_start[b] ..], and its entries [block_entry_start[b], block_entry_start[b + 1]):
  // value position, output and local direction.
  std::vector<int> blocks, block_input_start, block_input, block_row_start, block_row;
  std::vector<int> block_entry_start, block_entry_position, block_entry_output,
      block_entry_direction;
};

// Everything about SparseWeightedHessian for one (wrt, rows) that does not depend on the point.
struct SparseDerivatives::HessianPlan {
  unsigned wrt_bits = 0;
  bool all_rows = true;
  std::vector<int> rows;
  std::uint64_t last_use = 0;

  SparseMatrix pattern;  // columns x columns, both triangles, zero values
  int num_colors = 0;    // colours of a distance-2 colouring of the supports below
  // Outputs (of the subset) with a non-empty second-derivative pattern in the selected columns.
  std::vector<int> outputs;
  // Support of output outputs[o]: the inputs in its restricted second-derivative pairs,
  // support_input[support_start[o] .. support_start[o + 1]); all have distinct colours.
  std::vector<int> support_start, support_input;
  std::vector<int> input_color;  // per input, -1 if in no support
  // Pairs of output outputs[o]: pair_i/pair_j (inputs, i <= j) for e in
  // [pair_start[o], pair_start[o + 1]), with the positions of (i, j) and (j, i) in the pattern.
  std::vector<int> pair_start, pair_i, pair_j, position_ij, position_ji;
  // SparseHessianDirection (built at its first use): the outputs x columns pattern whose row
  // k holds the columns of k's support, and per support entry its column and value position.
  bool direction_ready = false;
  SparseMatrix direction_pattern;
  std::vector<int> support_column, support_position;
  // Functions made of blocks: the blocks of `outputs`; per block b its outputs outputs[
  // block_output_start[b] ..] and its support block_input[block_input_start[b] ..] (sorted union
  // of its outputs' supports); per pair e and support entry s the local indices of their
  // inputs in their block's support.
  std::vector<int> blocks, block_output_start, block_input_start, block_input;
  std::vector<int> pair_local_i, pair_local_j, support_local;
};

SparseDerivatives::SparseDerivatives() = default;
SparseDerivatives::~SparseDerivatives() = default;

void SparseDerivatives::UpdatePattern(TypedFunction* function, const ConstVectorRef& x,
                                      const ConstVectorRef& u, double t, const ConstVectorRef& p) {
  const int nx = static_cast<int>(x.size()), nu = static_cast<int>(u.size()),
            np = static_cast<int>(p.size());
  const bool fresh = !pattern_.SameSizes(nx, nu, np);
  if (!fresh && !pattern_.point_dependent) return;
  bool traced = false;
  if (fresh) {
    // The pattern the function's analysis holds (traced by this object or by a clone; the
    // function counts its traces in its stats).
    pattern_ = function->Analysis(x, u, t, p, &traced).pattern;
  }
  if (pattern_.point_dependent && !traced) {
    // A pattern that may change with the point: traced here as well, the stored one the union.
    SparsityPattern detected = DetectSparsity(function, x, u, t, p);
    ++stats_.num_detections;
    if (MergePattern(detected, &pattern_)) {
      ++stats_.num_pattern_growths;
    } else if (!fresh) {
      return;  // nothing new: the plans stay valid
    }
  }
  jacobian_plans_.clear();
  hessian_plans_.clear();
  const std::size_t n = static_cast<std::size_t>(pattern_.num_inputs);
  input_mark_.assign(n, 0);
  color_mark_.assign(n, 0);
  compact_color_.assign(n, -1);
  mark_stamp_ = 0;
}

SparseDerivatives::JacobianPlan& SparseDerivatives::FindJacobianPlan(const TypedFunction& function,
                                                                     Wrt wrt,
                                                                     const std::vector<int>* rows) {
  const unsigned bits = WrtBits(wrt);
  for (auto& plan : jacobian_plans_) {
    if (plan->wrt_bits == bits && plan->all_rows == (rows == nullptr) &&
        (rows == nullptr || plan->rows == *rows)) {
      plan->last_use = ++clock_;
      return *plan;
    }
  }
  auto plan = std::make_unique<JacobianPlan>();
  plan->wrt_bits = bits;
  plan->all_rows = rows == nullptr;
  const std::vector<int> selected = SelectedRows(function, rows);
  if (rows != nullptr) plan->rows = *rows;
  plan->last_use = ++clock_;

  int num_columns = 0;
  const std::vector<int> column_of = ColumnsOfInputs(pattern_, wrt, &num_columns);
  const int m = function.num_outputs();

  // Row-wise pattern of the selected rows (columns increase with inputs: sorted rows).
  std::vector<int> row_start{0}, row_column;
  for (int k : selected) {
    const auto k0 = static_cast<std::size_t>(k);
    for (int e = pattern_.jac_start[k0]; e < pattern_.jac_start[k0 + 1]; ++e) {
      const int column =
          column_of[static_cast<std::size_t>(pattern_.jac_inputs[static_cast<std::size_t>(e)])];
      if (column >= 0) row_column.push_back(column);
    }
    row_start.push_back(static_cast<int>(row_column.size()));
  }
  const bool blocked = UseBlocks(function);
  const std::vector<int> colors =
      blocked ? std::vector<int>(static_cast<std::size_t>(num_columns), -1)
              : ColorColumnsDistanceTwo(num_columns, row_start, row_column, &plan->num_colors);
  plan->num_passes = (plan->num_colors + kChunk - 1) / kChunk;

  // Compressed-column pattern (rows ascend within each column since `selected` ascends) and
  // the value position of every row-wise entry.
  std::vector<int> column_start(static_cast<std::size_t>(num_columns) + 1, 0);
  for (int column : row_column) ++column_start[static_cast<std::size_t>(column) + 1];
  for (int c = 0; c < num_columns; ++c) {
    column_start[static_cast<std::size_t>(c) + 1] += column_start[static_cast<std::size_t>(c)];
  }
  std::vector<int> fill(column_start.begin(), column_start.end() - 1);
  std::vector<int> row_index(row_column.size());
  std::vector<int> position(row_column.size());
  for (std::size_t r = 0; r < selected.size(); ++r) {
    for (int e = row_start[r]; e < row_start[r + 1]; ++e) {
      const int column = row_column[static_cast<std::size_t>(e)];
      const int at = fill[static_cast<std::size_t>(column)]++;
      row_index[static_cast<std::size_t>(at)] = selected[r];
      position[static_cast<std::size_t>(e)] = at;
    }
  }
  plan->pattern = PatternMatrix(m, num_columns, column_start, row_index);
  if (blocked) {
    AddJacobianBlocks(function, selected, row_start, row_column, position, column_of, plan.get());
  }

  // Entries grouped by pass (counting sort on colour / kChunk).
  const int passes = plan->num_passes;
  plan->entry_start.assign(static_cast<std::size_t>(passes) + 1, 0);
  for (int column : row_column) {
    if (blocked) break;
    ++plan->entry_start[static_cast<std::size_t>(colors[static_cast<std::size_t>(column)] /
                                                 kChunk) +
                        1];
  }
  for (int q = 0; q < passes; ++q) {
    plan->entry_start[static_cast<std::size_t>(q) + 1] +=
        plan->entry_start[static_cast<std::size_t>(q)];
  }
  const std::size_t entries = blocked ? 0 : row_column.size();
  plan->entry_position.resize(entries);
  plan->entry_output.resize(entries);
  plan->entry_direction.resize(entries);
  std::vector<int> next(plan->entry_start.begin(), plan->entry_start.end() - 1);
  for (std::size_t r = 0; r < selected.size() && !blocked; ++r) {
    for (int e = row_start[r]; e < row_start[r + 1]; ++e) {
      const int color = colors[static_cast<std::size_t>(row_column[static_cast<std::size_t>(e)])];
      const auto at = static_cast<std::size_t>(next[static_cast<std::size_t>(color / kChunk)]++);
      plan->entry_position[at] = position[static_cast<std::size_t>(e)];
      plan->entry_output[at] = selected[r];
      plan->entry_direction[at] = color % kChunk;
    }
  }

  // Seeded inputs grouped by pass.
  plan->seeded_start.assign(static_cast<std::size_t>(passes) + 1, 0);
  for (int i = 0; i < pattern_.num_inputs; ++i) {
    const int column = column_of[static_cast<std::size_t>(i)];
    if (column >= 0 && colors[static_cast<std::size_t>(column)] >= 0) {
      ++plan->seeded_start[static_cast<std::size_t>(colors[static_cast<std::size_t>(column)] /
                                                    kChunk) +
                           1];
    }
  }
  for (int q = 0; q < passes; ++q) {
    plan->seeded_start[static_cast<std::size_t>(q) + 1] +=
        plan->seeded_start[static_cast<std::size_t>(q)];
  }
  plan->seeded_input.resize(static_cast<std::size_t>(plan->seeded_start.back()));
  plan->seeded_direction.resize(plan->seeded_input.size());
  std::vector<int> seed_next(plan->seeded_start.begin(), plan->seeded_start.end() - 1);
  for (int i = 0; i < pattern_.num_inputs; ++i) {
    const int column = column_of[static_cast<std::size_t>(i)];
    if (column < 0 || colors[static_cast<std::size_t>(column)] < 0) continue;
    const int color = colors[static_cast<std::size_t>(column)];
    const auto at = static_cast<std::size_t>(seed_next[static_cast<std::size_t>(color / kChunk)]++);
    plan->seeded_input[at] = i;
    plan->seeded_direction[at] = color % kChunk;
  }

  if (static_cast<int>(jacobian_plans_.size()) >= kMaxPlansPerKind) {
    const auto oldest =
        std::min_element(jacobian_plans_.begin(), jacobian_plans_.end(),
                         [](const auto& a, const auto& b) { return a->last_use < b->last_use; });
    jacobian_plans_.erase(oldest);
  }
  jacobian_plans_.push_back(std::move(plan));
  return *jacobian_plans_.back();
}

SparseDerivatives::HessianPlan& SparseDerivatives::FindHessianPlan(const TypedFunction& function,
                                                                   Wrt wrt,
                                                                   const std::vector<int>* rows) {
  const unsigned bits = WrtBits(wrt);
  for (auto& plan : hessian_plans_) {
    if (plan->wrt_bits == bits && plan->all_rows == (rows == nullptr) &&
        (rows == nullptr || plan->rows == *rows)) {
      plan->last_use = ++clock_;
      return *plan;
    }
  }
  auto plan = std::make_unique<HessianPlan>();
  plan->wrt_bits = bits;
  plan->all_rows = rows == nullptr;
  const std::vector<int> selected = SelectedRows(function, rows);
  if (rows != nullptr) plan->rows = *rows;
  plan->last_use = ++clock_;

  int num_columns = 0;
  const std::vector<int> column_of = ColumnsOfInputs(pattern_, wrt, &num_columns);
  const std::size_t n = static_cast<std::size_t>(pattern_.num_inputs);

  // Pairs restricted to the selected columns, and the support of each output.
  std::vector<int> stamp(n, -1);
  plan->support_start.assign(1, 0);
  plan->pair_start.assign(1, 0);
  std::vector<std::pair<int, int>> union_entries;  // (column, row), both triangles
  for (int k : selected) {
    const auto k0 = static_cast<std::size_t>(k);
    const std::size_t pairs_before = plan->pair_i.size();
    const std::size_t support_before = plan->support_input.size();
    for (int e = pattern_.hess_start[k0]; e < pattern_.hess_start[k0 + 1]; ++e) {
      const int i = pattern_.hess_first[static_cast<std::size_t>(e)];
      const int j = pattern_.hess_second[static_cast<std::size_t>(e)];
      const int ci = column_of[static_cast<std::size_t>(i)];
      const int cj = column_of[static_cast<std::size_t>(j)];
      if (ci < 0 || cj < 0) continue;
      plan->pair_i.push_back(i);
      plan->pair_j.push_back(j);
      union_entries.emplace_back(cj, ci);
      if (ci != cj) union_entries.emplace_back(ci, cj);
      for (int input : {i, j}) {
        if (stamp[static_cast<std::size_t>(input)] != k) {
          stamp[static_cast<std::size_t>(input)] = k;
          plan->support_input.push_back(input);
        }
      }
    }
    if (plan->pair_i.size() == pairs_before) continue;
    std::sort(plan->support_input.begin() + static_cast<long>(support_before),
              plan->support_input.end());
    plan->outputs.push_back(k);
    plan->pair_start.push_back(static_cast<int>(plan->pair_i.size()));
    plan->support_start.push_back(static_cast<int>(plan->support_input.size()));
  }

  // Distance-2 colouring of the supports (inputs as columns): the inputs of every output have
  // distinct colours, so each output's second derivatives are read off the compressed ones.
  int num_colors = 0;
  if (UseBlocks(function)) {
    AddHessianBlocks(function, plan.get());
  } else {
    plan->input_color = ColorColumnsDistanceTwo(pattern_.num_inputs, plan->support_start,
                                                plan->support_input, &num_colors);
  }
  plan->num_colors = num_colors;

  // Union pattern (both triangles) and the value positions of every pair.
  std::sort(union_entries.begin(), union_entries.end());
  union_entries.erase(std::unique(union_entries.begin(), union_entries.end()), union_entries.end());
  std::vector<int> column_start(static_cast<std::size_t>(num_columns) + 1, 0);
  std::vector<int> row_index(union_entries.size());
  for (std::size_t e = 0; e < union_entries.size(); ++e) {
    ++column_start[static_cast<std::size_t>(union_entries[e].first) + 1];
    row_index[e] = union_entries[e].second;
  }
  for (int c = 0; c < num_columns; ++c) {
    column_start[static_cast<std::size_t>(c) + 1] += column_start[static_cast<std::size_t>(c)];
  }
  plan->pattern = PatternMatrix(num_columns, num_columns, column_start, row_index);
  auto position = [&](int row, int column) {
    const auto begin = row_index.begin() + column_start[static_cast<std::size_t>(column)];
    const auto end = row_index.begin() + column_start[static_cast<std::size_t>(column) + 1];
    const auto found = std::lower_bound(begin, end, row);
    MOREAU_ASSERT(found != end && *found == row, "Hessian pair missing from its pattern");
    return static_cast<int>(found - row_index.begin());
  };
  plan->position_ij.resize(plan->pair_i.size());
  plan->position_ji.resize(plan->pair_i.size());
  for (std::size_t e = 0; e < plan->pair_i.size(); ++e) {
    const int ci = column_of[static_cast<std::size_t>(plan->pair_i[e])];
    const int cj = column_of[static_cast<std::size_t>(plan->pair_j[e])];
    plan->position_ij[e] = position(ci, cj);
    plan->position_ji[e] = position(cj, ci);
  }

  if (static_cast<int>(hessian_plans_.size()) >= kMaxPlansPerKind) {
    const auto oldest =
        std::min_element(hessian_plans_.begin(), hessian_plans_.end(),
                         [](const auto& a, const auto& b) { return a->last_use < b->last_use; });
    hessian_plans_.erase(oldest);
  }
  hessian_plans_.push_back(std::move(plan));
  return *hessian_plans_.back();
}

void SparseDerivatives::GatherInputValues(const ConstVectorRef& x, const ConstVectorRef& u,
                                          double t, const ConstVectorRef& p) {
  input_values_.resize(static_cast<std::size_t>(pattern_.num_inputs));
  std::size_t i = 0;
  for (Eigen::Index k = 0; k < x.size(); ++k) input_values_[i++] = x[k];
  for (Eigen::Index k = 0; k < u.size(); ++k) input_values_[i++] = u[k];
  input_values_[i++] = t;
  for (Eigen::Index k = 0; k < p.size(); ++k) input_values_[i++] = p[k];
}

void SparseDerivatives::FillInputs1(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                    const ConstVectorRef& p) {
  GatherInputValues(x, u, t, p);
  const std::size_t n = static_cast<std::size_t>(pattern_.num_inputs);
  inputs1_.resize(n);
  for (std::size_t k = 0; k < n; ++k) inputs1_[k] = Dual1(input_values_[k]);
}

void SparseDerivatives::FillBlockInputs1(unsigned wrt_bits, std::vector<Dual1>* inputs,
                                         bool clean) const {
  const std::size_t n = input_values_.size();
  if (!clean || inputs->size() != n) {
    inputs->resize(n);
    for (std::size_t k = 0; k < n; ++k) (*inputs)[k] = Dual1(input_values_[k]);
    return;
  }
  // Argument blocks x | u | t | p; those not differentiated are read as constants.
  const std::size_t sizes[4] = {static_cast<std::size_t>(pattern_.nx),
                                static_cast<std::size_t>(pattern_.nu), 1,
                                static_cast<std::size_t>(pattern_.np)};
  std::size_t first = 0;
  for (unsigned block = 0; block < 4; ++block) {
    if (((wrt_bits >> block) & 1u) == 0) {
      for (std::size_t k = first; k < first + sizes[block]; ++k) {
        (*inputs)[k] = Dual1(input_values_[k]);
      }
    }
    first += sizes[block];
  }
}

void SparseDerivatives::FillInputs2(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                                    const ConstVectorRef& p) {
  const std::size_t n = static_cast<std::size_t>(pattern_.num_inputs);
  input_values_.resize(n);
  std::size_t i = 0;
  for (Eigen::Index k = 0; k < x.size(); ++k) input_values_[i++] = x[k];
  for (Eigen::Index k = 0; k < u.size(); ++k) input_values_[i++] = u[k];
  input_values_[i++] = t;
  for (Eigen::Index k = 0; k < p.size(); ++k) input_values_[i++] = p[k];
  inputs2_.resize(n);
  for (std::size_t k = 0; k < n; ++k) inputs2_[k] = Dual2(input_values_[k]);
}

// ---- Jacobian -----------------------------------------------------------------------------

void SparseDerivatives::Jacobian(TypedFunction* function, const ConstVectorRef& x,
                                 const ConstVectorRef& u, double t, const ConstVectorRef& p,
                                 Wrt wrt, Vector* out, SparseMatrix* jac,
                                 const std::vector<int>* rows, ThreadPool* pool) {
  UpdatePattern(function, x, u, t, p);
  const JacobianPlan& plan = FindJacobianPlan(*function, wrt, rows);
  AdoptPattern(plan.pattern, jac);
  stats_.jacobian_colors = plan.num_colors;
  stats_.jacobian_passes = plan.num_passes;
  if (UseBlocks(*function)) {
    GatherInputValues(x, u, t, p);
    FillBlockInputs1(plan.wrt_bits, &inputs1_, inputs1_clean_);
    inputs1_clean_ = false;  // until every block's seeds are reset
    BlockJacobian(function, plan, out, jac->valuePtr(), pool);
    inputs1_clean_ = true;
    return;
  }
  if (plan.num_passes == 0) {  // nothing to differentiate: the value only
    function->Evaluate(x, u, t, p, out);
    return;
  }
  const int m = function->num_outputs();
  const int nx = pattern_.nx, nu = pattern_.nu, np = pattern_.np;
  out->resize(m);
  double* values = jac->valuePtr();
  FillInputs1(x, u, t, p);
  inputs1_clean_ = false;  // until the last pass's seeds are reset
  outputs1_.resize(static_cast<std::size_t>(m));
  for (int q = 0; q < plan.num_passes; ++q) {
    // One direction per colour of this chunk; every other input is a constant.
    const int directions = std::min(kChunk, plan.num_colors - q * kChunk);
    const auto s0 = static_cast<std::size_t>(plan.seeded_start[static_cast<std::size_t>(q)]);
    const auto s1 = static_cast<std::size_t>(plan.seeded_start[static_cast<std::size_t>(q) + 1]);
    for (std::size_t s = s0; s < s1; ++s) {
      const auto i = static_cast<std::size_t>(plan.seeded_input[s]);
      inputs1_[i] = Dual1::Variable(input_values_[i], directions, plan.seeded_direction[s]);
    }
    std::fill(outputs1_.begin(), outputs1_.end(), Dual1(0.0));
    const Dual1* base = inputs1_.data();
    function->Call(base, nx, base + nx, nu, base[static_cast<std::size_t>(nx + nu)],
                   base + nx + nu + 1, np, outputs1_.data());
    if (q == 0) {
      for (int k = 0; k < m; ++k) (*out)[k] = outputs1_[static_cast<std::size_t>(k)].value();
    }
    // Direct recovery: in every row, the colour of an entry's column is that column's alone.
    const auto e0 = static_cast<std::size_t>(plan.entry_start[static_cast<std::size_t>(q)]);
    const auto e1 = static_cast<std::size_t>(plan.entry_start[static_cast<std::size_t>(q) + 1]);
    for (std::size_t e = e0; e < e1; ++e) {
      const Dual1& g = outputs1_[static_cast<std::size_t>(plan.entry_output[e])];
      const int direction = plan.entry_direction[e];
      values[plan.entry_position[e]] = direction < g.size() ? g.d(direction) : 0.0;
    }
    for (std::size_t s = s0; s < s1; ++s) {
      const auto i = static_cast<std::size_t>(plan.seeded_input[s]);
      inputs1_[i] = Dual1(input_values_[i]);
    }
  }
  inputs1_clean_ = true;
}

// ---- weighted Hessian ---------------------------------------------------------------------

void SparseDerivatives::WeightedHessian(TypedFunction* function, const ConstVectorRef& x,
                                        const ConstVectorRef& u, double t, const ConstVectorRef& p,
                                        Wrt wrt, const ConstVectorRef& weights, SparseMatrix* hess,
                                        const std::vector<int>* rows) {
  UpdatePattern(function, x, u, t, p);
  const HessianPlan& plan = FindHessianPlan(*function, wrt, rows);
  AdoptPattern(plan.pattern, hess);
  double* values = hess->valuePtr();
  std::fill(values, values + hess->nonZeros(), 0.0);
  stats_.hessian_colors = 0;
  stats_.hessian_passes = 0;
  if (UseBlocks(*function)) {
    BlockWeightedHessian(function, plan, x, u, t, p, weights, values);
    return;
  }

  // Outputs with a nonzero weight, their inputs (seeded) and the colours those use, renumbered
  // 0, 1, ... in increasing colour order so that only they take directions.
  if (++mark_stamp_ == 0) {  // wrapped: reset the marks
    std::fill(input_mark_.begin(), input_mark_.end(), 0);
    std::fill(color_mark_.begin(), color_mark_.end(), 0);
    mark_stamp_ = 1;
  }
  active_outputs_.clear();
  seeded_.clear();
  used_colors_.clear();
  for (std::size_t o = 0; o < plan.outputs.size(); ++o) {
    if (weights[plan.outputs[o]] == 0.0) continue;
    active_outputs_.push_back(static_cast<int>(o));
    for (int s = plan.support_start[o]; s < plan.support_start[o + 1]; ++s) {
      const int i = plan.support_input[static_cast<std::size_t>(s)];
      if (input_mark_[static_cast<std::size_t>(i)] == mark_stamp_) continue;
      input_mark_[static_cast<std::size_t>(i)] = mark_stamp_;
      seeded_.push_back(i);
      const int color = plan.input_color[static_cast<std::size_t>(i)];
      if (color_mark_[static_cast<std::size_t>(color)] != mark_stamp_) {
        color_mark_[static_cast<std::size_t>(color)] = mark_stamp_;
        used_colors_.push_back(color);
      }
    }
  }
  if (active_outputs_.empty()) return;  // zero weights: no derivative work at all
  std::sort(used_colors_.begin(), used_colors_.end());
  const int colors = static_cast<int>(used_colors_.size());
  for (int c = 0; c < colors; ++c) {
    compact_color_[static_cast<std::size_t>(used_colors_[static_cast<std::size_t>(c)])] = c;
  }
  auto compact = [&](int input) {
    return compact_color_[static_cast<std::size_t>(
        plan.input_color[static_cast<std::size_t>(input)])];
  };
  const int chunks = (colors + kChunk - 1) / kChunk;
  stats_.hessian_colors = colors;
  // The chunk pairs (a <= b) that hold some pair of an active output: only those are evaluated
  // (a Hessian whose pairs are all diagonal needs the diagonal chunks only).
  needed_chunk_pairs_.assign(static_cast<std::size_t>(chunks * chunks), 0);
  for (int o : active_outputs_) {
    for (int e = plan.pair_start[static_cast<std::size_t>(o)];
         e < plan.pair_start[static_cast<std::size_t>(o) + 1]; ++e) {
      const int a = compact(plan.pair_i[static_cast<std::size_t>(e)]) / kChunk;
      const int b = compact(plan.pair_j[static_cast<std::size_t>(e)]) / kChunk;
      needed_chunk_pairs_[static_cast<std::size_t>(std::min(a, b) * chunks + std::max(a, b))] = 1;
    }
  }

  const int m = function->num_outputs();
  const int nx = pattern_.nx, nu = pattern_.nu, np = pattern_.np;
  FillInputs2(x, u, t, p);
  outputs2_.resize(static_cast<std::size_t>(m));
  // Outer level seeds the colours of chunk a, inner level those of chunk b >= a (symmetry).
  for (int a = 0; a < chunks; ++a) {
    const int outer_size = std::min(kChunk, colors - a * kChunk);
    for (int b = a; b < chunks; ++b) {
      if (!needed_chunk_pairs_[static_cast<std::size_t>(a * chunks + b)]) continue;
      const int inner_size = std::min(kChunk, colors - b * kChunk);
      for (int i : seeded_) {
        const int c = compact(i);
        const int chunk = c / kChunk;
        if (chunk != a && chunk != b) continue;
        const double value = input_values_[static_cast<std::size_t>(i)];
        const Dual1 inner =
            chunk == b ? Dual1::Variable(value, inner_size, c % kChunk) : Dual1(value);
        inputs2_[static_cast<std::size_t>(i)] =
            chunk == a ? Dual2::Variable(inner, outer_size, c % kChunk) : Dual2(inner);
      }
      std::fill(outputs2_.begin(), outputs2_.end(), Dual2(0.0));
      const Dual2* base = inputs2_.data();
      function->Call(base, nx, base + nx, nu, base[static_cast<std::size_t>(nx + nu)],
                     base + nx + nu + 1, np, outputs2_.data());
      ++stats_.hessian_passes;
      // Per-output direct recovery of the pairs whose colours fall in chunks (a, b).
      for (int o : active_outputs_) {
        const int k = plan.outputs[static_cast<std::size_t>(o)];
        const double w = weights[k];
        const Dual2& g = outputs2_[static_cast<std::size_t>(k)];
        for (int e = plan.pair_start[static_cast<std::size_t>(o)];
             e < plan.pair_start[static_cast<std::size_t>(o) + 1]; ++e) {
          const auto ue = static_cast<std::size_t>(e);
          int ci = compact(plan.pair_i[ue]);
          int cj = compact(plan.pair_j[ue]);
          if (ci / kChunk != a) std::swap(ci, cj);  // ci: the outer one
          if (ci / kChunk != a || cj / kChunk != b) continue;
          AddSecondDerivative(g, ci % kChunk, cj % kChunk, w, plan.position_ij[ue],
                              plan.position_ji[ue], values);
        }
      }
      for (int i : seeded_)
        inputs2_[static_cast<std::size_t>(i)] = Dual2(input_values_[static_cast<std::size_t>(i)]);
    }
  }
}

// ---- second derivatives along a direction ----------------------------------------------

void SparseDerivatives::HessianDirection(TypedFunction* function, const ConstVectorRef& x,
                                         const ConstVectorRef& u, double t, const ConstVectorRef& p,
                                         Wrt wrt, const ConstVectorRef& direction,
                                         SparseMatrix* rows_matrix, const std::vector<int>* rows) {
  UpdatePattern(function, x, u, t, p);
  HessianPlan& plan = FindHessianPlan(*function, wrt, rows);
  const int m = function->num_outputs();
  if (!plan.direction_ready) {
    // Row k of the result holds the selected columns of k's support (sorted inputs give
    // sorted columns: the selected blocks keep the input order).
    int num_columns = 0;
    const std::vector<int> column_of = ColumnsOfInputs(pattern_, wrt, &num_columns);
    std::vector<std::pair<int, int>> entries;  // (column, row)
    plan.support_column.resize(plan.support_input.size());
    for (std::size_t o = 0; o < plan.outputs.size(); ++o) {
      for (int s = plan.support_start[o]; s < plan.support_start[o + 1]; ++s) {
        const int column =
            column_of[static_cast<std::size_t>(plan.support_input[static_cast<std::size_t>(s)])];
        plan.support_column[static_cast<std::size_t>(s)] = column;
        entries.emplace_back(column, plan.outputs[o]);
      }
    }
    std::sort(entries.begin(), entries.end());
    std::vector<int> column_start(static_cast<std::size_t>(num_columns) + 1, 0);
    std::vector<int> row_index(entries.size());
    for (std::size_t e = 0; e < entries.size(); ++e) {
      ++column_start[static_cast<std::size_t>(entries[e].first) + 1];
      row_index[e] = entries[e].second;
    }
    for (int c = 0; c < num_columns; ++c) {
      column_start[static_cast<std::size_t>(c) + 1] += column_start[static_cast<std::size_t>(c)];
    }
    plan.direction_pattern = PatternMatrix(m, num_columns, column_start, row_index);
    plan.support_position.resize(plan.support_input.size());
    for (std::size_t o = 0; o < plan.outputs.size(); ++o) {
      for (int s = plan.support_start[o]; s < plan.support_start[o + 1]; ++s) {
        const int column = plan.support_column[static_cast<std::size_t>(s)];
        const auto begin = row_index.begin() + column_start[static_cast<std::size_t>(column)];
        const auto end = row_index.begin() + column_start[static_cast<std::size_t>(column) + 1];
        const auto found = std::lower_bound(begin, end, plan.outputs[o]);
        MOREAU_ASSERT(found != end && *found == plan.outputs[o], "support entry missing");
        plan.support_position[static_cast<std::size_t>(s)] =
            static_cast<int>(found - row_index.begin());
      }
    }
    plan.direction_ready = true;
  }
  AdoptPattern(plan.direction_pattern, rows_matrix);
  double* values = rows_matrix->valuePtr();
  std::fill(values, values + rows_matrix->nonZeros(), 0.0);
  if (UseBlocks(*function)) {
    if (plan.outputs.empty()) return;
    FillInputs2(x, u, t, p);
    BlockHessianDirection(function, plan, direction, values);
    return;
  }
  if (plan.outputs.empty() || plan.num_colors == 0) return;

  // Outer level: the colours of chunk a (inputs of one output have distinct colours); inner
  // level: the one direction, so that d/d(colour c) of (grad g_k . direction) is entry
  // (k, i_c) of H_k direction, i_c the input of colour c in k's support.
  const int nx = pattern_.nx, nu = pattern_.nu, np = pattern_.np;
  FillInputs2(x, u, t, p);
  outputs2_.resize(static_cast<std::size_t>(m));
  const int chunks = (plan.num_colors + kChunk - 1) / kChunk;
  // Inputs in some support, each once (their inner seed is the direction's entry).
  if (++mark_stamp_ == 0) {
    std::fill(input_mark_.begin(), input_mark_.end(), 0);
    std::fill(color_mark_.begin(), color_mark_.end(), 0);
    mark_stamp_ = 1;
  }
  seeded_.clear();
  std::vector<int>& seeded_column = seeded_column_;
  seeded_column.clear();
  for (std::size_t s = 0; s < plan.support_input.size(); ++s) {
    const int i = plan.support_input[s];
    if (input_mark_[static_cast<std::size_t>(i)] == mark_stamp_) continue;
    input_mark_[static_cast<std::size_t>(i)] = mark_stamp_;
    seeded_.push_back(i);
    seeded_column.push_back(plan.support_column[s]);
  }
  stats_.hessian_colors = plan.num_colors;
  stats_.hessian_passes = 0;
  for (int a = 0; a < chunks; ++a) {
    const int outer_size = std::min(kChunk, plan.num_colors - a * kChunk);
    for (std::size_t q = 0; q < seeded_.size(); ++q) {
      const auto i = static_cast<std::size_t>(seeded_[q]);
      const double d = direction[seeded_column[q]];
      const int color = plan.input_color[i];
      Dual1 inner(input_values_[i]);
      if (d != 0.0) {
        inner = Dual1(input_values_[i], 1);
        inner.d(0) = d;
      }
      inputs2_[i] =
          color / kChunk == a ? Dual2::Variable(inner, outer_size, color % kChunk) : Dual2(inner);
    }
    std::fill(outputs2_.begin(), outputs2_.end(), Dual2(0.0));
    const Dual2* base = inputs2_.data();
    function->Call(base, nx, base + nx, nu, base[static_cast<std::size_t>(nx + nu)],
                   base + nx + nu + 1, np, outputs2_.data());
    ++stats_.hessian_passes;
    for (std::size_t o = 0; o < plan.outputs.size(); ++o) {
      const Dual2& g = outputs2_[static_cast<std::size_t>(plan.outputs[o])];
      for (int s = plan.support_start[o]; s < plan.support_start[o + 1]; ++s) {
        const int color = plan.input_color[static_cast<std::size_t>(
            plan.support_input[static_cast<std::size_t>(s)])];
        if (color / kChunk != a) continue;
        const int outer = color % kChunk;
        if (outer >= g.size()) continue;
        const Dual1& row = g.d(outer);
        if (row.size() > 0) values[plan.support_position[static_cast<std::size_t>(s)]] = row.d(0);
      }
    }
  }
  for (int i : seeded_) {
    inputs2_[static_cast<std::size_t>(i)] = Dual2(input_values_[static_cast<std::size_t>(i)]);
  }
}

// ---- functions made of blocks -------------------------------------------------------------

namespace {
// The column of `input` for the selected blocks `wrt_bits` (ColumnsOfInputs for one input); the
// input must be in a selected block.
int ColumnOfInput(const SparsityPattern& pattern, unsigned wrt_bits, int input) {
  const int sizes[4] = {pattern.nx, pattern.nu, 1, pattern.np};
  int first_input = 0, first_column = 0;
  for (int block = 0; block < 4; ++block) {
    const bool selected = ((wrt_bits >> block) & 1u) != 0;
    if (input < first_input + sizes[block]) {
      MOREAU_ASSERT(selected, "input of an unselected block has no column");
      return first_column + input - first_input;
    }
    first_input += sizes[block];
    if (selected) first_column += sizes[block];
  }
  MOREAU_ASSERT(false, "input out of range");
  return -1;
}
}  // namespace

bool SparseDerivatives::UseBlocks(const TypedFunction& function) const {
  return function.block_outputs() > 0 && !pattern_.point_dependent;
}

void SparseDerivatives::AddJacobianBlocks(
    const TypedFunction& function, const std::vector<int>& selected,
    const std::vector<int>& row_start, const std::vector<int>& row_column,
    const std::vector<int>& position, const std::vector<int>& column_of, JacobianPlan* plan) const {
  const int per_block = function.block_outputs();
  std::vector<int> input_of_column;
  for (std::size_t i = 0; i < column_of.size(); ++i) {
    if (column_of[i] >= 0) {
      input_of_column.resize(static_cast<std::size_t>(column_of[i]) + 1);
      input_of_column[static_cast<std::size_t>(column_of[i])] = static_cast<int>(i);
    }
  }
  plan->block_input_start.assign(1, 0);
  plan->block_row_start.assign(1, 0);
  plan->block_entry_start.assign(1, 0);
  std::vector<int> inputs;
  for (std::size_t r0 = 0; r0 < selected.size();) {
    const int block = selected[r0] / per_block;
    std::size_t r1 = r0;
    while (r1 < selected.size() && selected[r1] / per_block == block) ++r1;
    // The block's inputs in the selected columns (sorted, unique).
    inputs.clear();
    for (std::size_t r = r0; r < r1; ++r) {
      for (int e = row_start[r]; e < row_start[r + 1]; ++e) {
        inputs.push_back(
            input_of_column[static_cast<std::size_t>(row_column[static_cast<std::size_t>(e)])]);
      }
    }
    std::sort(inputs.begin(), inputs.end());
    inputs.erase(std::unique(inputs.begin(), inputs.end()), inputs.end());
    plan->blocks.push_back(block);
    plan->block_input.insert(plan->block_input.end(), inputs.begin(), inputs.end());
    plan->block_input_start.push_back(static_cast<int>(plan->block_input.size()));
    for (std::size_t r = r0; r < r1; ++r) {
      plan->block_row.push_back(selected[r]);
      for (int e = row_start[r]; e < row_start[r + 1]; ++e) {
        const int input =
            input_of_column[static_cast<std::size_t>(row_column[static_cast<std::size_t>(e)])];
        plan->block_entry_position.push_back(position[static_cast<std::size_t>(e)]);
        plan->block_entry_output.push_back(selected[r]);
        plan->block_entry_direction.push_back(static_cast<int>(
            std::lower_bound(inputs.begin(), inputs.end(), input) - inputs.begin()));
      }
    }
    plan->block_row_start.push_back(static_cast<int>(plan->block_row.size()));
    plan->block_entry_start.push_back(static_cast<int>(plan->block_entry_position.size()));
    r0 = r1;
  }
}

void SparseDerivatives::AddHessianBlocks(const TypedFunction& function, HessianPlan* plan) const {
  const int per_block = function.block_outputs();
  plan->block_output_start.assign(1, 0);
  plan->block_input_start.assign(1, 0);
  plan->pair_local_i.resize(plan->pair_i.size());
  plan->pair_local_j.resize(plan->pair_i.size());
  plan->support_local.resize(plan->support_input.size());
  std::vector<int> inputs;
  const std::size_t num_outputs = plan->outputs.size();
  for (std::size_t o0 = 0; o0 < num_outputs;) {
    const int block = plan->outputs[o0] / per_block;
    std::size_t o1 = o0;
    while (o1 < num_outputs && plan->outputs[o1] / per_block == block) ++o1;
    inputs.assign(plan->support_input.begin() + plan->support_start[o0],
                  plan->support_input.begin() + plan->support_start[o1]);
    std::sort(inputs.begin(), inputs.end());
    inputs.erase(std::unique(inputs.begin(), inputs.end()), inputs.end());
    auto local = [&inputs](int input) {
      return static_cast<int>(std::lower_bound(inputs.begin(), inputs.end(), input) -
                              inputs.begin());
    };
    for (std::size_t o = o0; o < o1; ++o) {
      for (int e = plan->pair_start[o]; e < plan->pair_start[o + 1]; ++e) {
        const auto ue = static_cast<std::size_t>(e);
        plan->pair_local_i[ue] = local(plan->pair_i[ue]);
        plan->pair_local_j[ue] = local(plan->pair_j[ue]);
      }
      for (int s = plan->support_start[o]; s < plan->support_start[o + 1]; ++s) {
        const auto us = static_cast<std::size_t>(s);
        plan->support_local[us] = local(plan->support_input[us]);
      }
    }
    plan->blocks.push_back(block);
    plan->block_output_start.push_back(static_cast<int>(o1));
    plan->block_input.insert(plan->block_input.end(), inputs.begin(), inputs.end());
    plan->block_input_start.push_back(static_cast<int>(plan->block_input.size()));
    o0 = o1;
  }
}

void SparseDerivatives::BlockJacobian(TypedFunction* function, const JacobianPlan& plan,
                                      Vector* out, double* values, ThreadPool* pool) {
  const int m = function->num_outputs();
  const int per_block = function->block_outputs();
  const int nx = pattern_.nx, nu = pattern_.nu, np = pattern_.np;
  // Values of the rows asked for; the others are not computed.
  out->resize(m);
  if (!plan.all_rows) out->setConstant(std::numeric_limits<double>::quiet_NaN());
  const int num_blocks = static_cast<int>(plan.blocks.size());
  // Threads only where the blocks are many: a parallel loop costs some microseconds.
  const int threads = pool != nullptr && num_blocks >= kParallelMinBlocks ? pool->threads() : 1;
  if (static_cast<int>(block_workspaces_.size()) < threads) {
    block_workspaces_.resize(static_cast<std::size_t>(threads));
  }
  for (BlockWorkspace& space : block_workspaces_) space.has_inputs = false;
  auto body = [&](int begin, int end, int thread) {
    BlockWorkspace& space = block_workspaces_[static_cast<std::size_t>(thread)];
    std::vector<Dual1>& inputs = thread == 0 ? inputs1_ : space.inputs1;
    if (thread > 0 && !space.has_inputs) {
      // This thread's constant copy of the inputs (thread 0's is inputs1_), brought up to date
      // at its first chunk of this call: a worker that finds the chunks taken copies nothing.
      FillBlockInputs1(plan.wrt_bits, &inputs, space.clean);
      space.has_inputs = true;
    }
    if (thread > 0) space.clean = false;  // until this chunk's seeds are reset
    std::vector<Dual1>& outputs = space.outputs1;
    outputs.resize(static_cast<std::size_t>(per_block));
    const Dual1* base = inputs.data();
    for (int b = begin; b < end; ++b) {
      const auto ub = static_cast<std::size_t>(b);
      const int first_input = plan.block_input_start[ub];
      const int count = plan.block_input_start[ub + 1] - first_input;
      const int first_output = plan.blocks[ub] * per_block;
      // Inputs beyond the first chunk are constants in it: current values (FillBlockInputs1
      // leaves the differentiated inputs as they were).
      for (int j = kChunk; j < count; ++j) {
        const auto i =
            static_cast<std::size_t>(plan.block_input[static_cast<std::size_t>(first_input + j)]);
        inputs[i] = Dual1(input_values_[i]);
      }
      // At least one pass (the values), chunks of kChunk directions.
      for (int c0 = 0; c0 == 0 || c0 < count; c0 += kChunk) {
        const int directions = std::min(kChunk, count - c0);
        for (int j = 0; j < directions; ++j) {
          const auto i = static_cast<std::size_t>(
              plan.block_input[static_cast<std::size_t>(first_input + c0 + j)]);
          inputs[i] = Dual1::Variable(input_values_[i], directions, j);
        }
        for (Dual1& value : outputs) value = Dual1(0.0);
        function->CallBlock(plan.blocks[ub], base, nx, base + nx, nu,
                            base[static_cast<std::size_t>(nx + nu)], base + nx + nu + 1, np,
                            outputs.data());
        if (c0 == 0) {
          for (int r = plan.block_row_start[ub]; r < plan.block_row_start[ub + 1]; ++r) {
            const int row = plan.block_row[static_cast<std::size_t>(r)];
            (*out)[row] = outputs[static_cast<std::size_t>(row - first_output)].value();
          }
        }
        for (int e = plan.block_entry_start[ub]; e < plan.block_entry_start[ub + 1]; ++e) {
          const auto ue = static_cast<std::size_t>(e);
          const int direction = plan.block_entry_direction[ue] - c0;
          if (direction < 0 || direction >= directions) continue;
          const Dual1& g =
              outputs[static_cast<std::size_t>(plan.block_entry_output[ue] - first_output)];
          values[plan.block_entry_position[ue]] = direction < g.size() ? g.d(direction) : 0.0;
        }
        for (int j = 0; j < directions; ++j) {
          const auto i = static_cast<std::size_t>(
              plan.block_input[static_cast<std::size_t>(first_input + c0 + j)]);
          inputs[i] = Dual1(input_values_[i]);
        }
      }
    }
    if (thread > 0) space.clean = true;
  };
  if (threads > 1) {
    pool->ParallelFor(num_blocks, body);
  } else {
    body(0, num_blocks, 0);
  }
}

void SparseDerivatives::BlockWeightedHessian(TypedFunction* function, const HessianPlan& plan,
                                             const ConstVectorRef& x, const ConstVectorRef& u,
                                             double t, const ConstVectorRef& p,
                                             const ConstVectorRef& weights, double* values) {
  const int per_block = function->block_outputs();
  const int nx = pattern_.nx, nu = pattern_.nu, np = pattern_.np;
  bool filled = false;
  block_outputs2_.resize(static_cast<std::size_t>(per_block));
  const Dual2* base = inputs2_.data();
  for (std::size_t b = 0; b < plan.blocks.size(); ++b) {
    const int o0 = plan.block_output_start[b], o1 = plan.block_output_start[b + 1];
    bool active = false;
    for (int o = o0; o < o1 && !active; ++o) {
      active = weights[plan.outputs[static_cast<std::size_t>(o)]] != 0.0;
    }
    if (!active) continue;  // zero weights: no derivative work
    if (!filled) {
      FillInputs2(x, u, t, p);
      base = inputs2_.data();
      filled = true;
    }
    const int first_input = plan.block_input_start[b];
    const int count = plan.block_input_start[b + 1] - first_input;
    const int first_output = plan.blocks[b] * per_block;
    const int chunks = (count + kChunk - 1) / kChunk;
    ++stats_.hessian_passes;
    // Outer level seeds the local directions of chunk a, inner level those of chunk c >= a.
    for (int a = 0; a < chunks; ++a) {
      const int outer_size = std::min(kChunk, count - a * kChunk);
      for (int c = a; c < chunks; ++c) {
        const int inner_size = std::min(kChunk, count - c * kChunk);
        for (int j = 0; j < count; ++j) {
          const int chunk = j / kChunk;
          if (chunk != a && chunk != c) continue;
          const auto i =
              static_cast<std::size_t>(plan.block_input[static_cast<std::size_t>(first_input + j)]);
          const double value = input_values_[i];
          const Dual1 inner =
              chunk == c ? Dual1::Variable(value, inner_size, j % kChunk) : Dual1(value);
          inputs2_[i] = chunk == a ? Dual2::Variable(inner, outer_size, j % kChunk) : Dual2(inner);
        }
        for (Dual2& value : block_outputs2_) value = Dual2(0.0);
        function->CallBlock(plan.blocks[b], base, nx, base + nx, nu,
                            base[static_cast<std::size_t>(nx + nu)], base + nx + nu + 1, np,
                            block_outputs2_.data());
        for (int o = o0; o < o1; ++o) {
          const int k = plan.outputs[static_cast<std::size_t>(o)];
          const double w = weights[k];
          if (w == 0.0) continue;
          const Dual2& g = block_outputs2_[static_cast<std::size_t>(k - first_output)];
          for (int e = plan.pair_start[static_cast<std::size_t>(o)];
               e < plan.pair_start[static_cast<std::size_t>(o) + 1]; ++e) {
            const auto ue = static_cast<std::size_t>(e);
            int li = plan.pair_local_i[ue], lj = plan.pair_local_j[ue];
            if (li / kChunk != a) std::swap(li, lj);  // li: the outer one
            if (li / kChunk != a || lj / kChunk != c) continue;
            AddSecondDerivative(g, li % kChunk, lj % kChunk, w, plan.position_ij[ue],
                                plan.position_ji[ue], values);
          }
        }
        for (int j = 0; j < count; ++j) {
          const auto i =
              static_cast<std::size_t>(plan.block_input[static_cast<std::size_t>(first_input + j)]);
          inputs2_[i] = Dual2(input_values_[i]);
        }
      }
    }
  }
}

void SparseDerivatives::BlockHessianDirection(TypedFunction* function, const HessianPlan& plan,
                                              const ConstVectorRef& direction, double* values) {
  const int per_block = function->block_outputs();
  const int nx = pattern_.nx, nu = pattern_.nu, np = pattern_.np;
  block_outputs2_.resize(static_cast<std::size_t>(per_block));
  const Dual2* base = inputs2_.data();
  stats_.hessian_passes = 0;
  for (std::size_t b = 0; b < plan.blocks.size(); ++b) {
    const int first_input = plan.block_input_start[b];
    const int count = plan.block_input_start[b + 1] - first_input;
    const int first_output = plan.blocks[b] * per_block;
    const int o0 = plan.block_output_start[b], o1 = plan.block_output_start[b + 1];
    // Outer level: the block's inputs (chunks of kChunk); inner level: the one direction.
    for (int c0 = 0; c0 < count; c0 += kChunk) {
      const int outer_size = std::min(kChunk, count - c0);
      for (int j = 0; j < count; ++j) {
        const auto i =
            static_cast<std::size_t>(plan.block_input[static_cast<std::size_t>(first_input + j)]);
        Dual1 inner(input_values_[i]);
        const double d = direction[ColumnOfInput(pattern_, plan.wrt_bits, static_cast<int>(i))];
        if (d != 0.0) {
          inner = Dual1(input_values_[i], 1);
          inner.d(0) = d;
        }
        inputs2_[i] = j >= c0 && j < c0 + outer_size ? Dual2::Variable(inner, outer_size, j - c0)
                                                     : Dual2(inner);
      }
      for (Dual2& value : block_outputs2_) value = Dual2(0.0);
      function->CallBlock(plan.blocks[b], base, nx, base + nx, nu,
                          base[static_cast<std::size_t>(nx + nu)], base + nx + nu + 1, np,
                          block_outputs2_.data());
      ++stats_.hessian_passes;
      for (int o = o0; o < o1; ++o) {
        const int k = plan.outputs[static_cast<std::size_t>(o)];
        const Dual2& g = block_outputs2_[static_cast<std::size_t>(k - first_output)];
        for (int s = plan.support_start[static_cast<std::size_t>(o)];
             s < plan.support_start[static_cast<std::size_t>(o) + 1]; ++s) {
          const int outer = plan.support_local[static_cast<std::size_t>(s)] - c0;
          if (outer < 0 || outer >= outer_size || outer >= g.size()) continue;
          const Dual1& row = g.d(outer);
          if (row.size() > 0) values[plan.support_position[static_cast<std::size_t>(s)]] = row.d(0);
        }
      }
    }
    for (int j = 0; j < count; ++j) {
      const auto i =
          static_cast<std::size_t>(plan.block_input[static_cast<std::size_t>(first_input + j)]);
      inputs2_[i] = Dual2(input_values_[i]);
    }
  }
}

SparseDerivativeStats SparseDerivatives::stats() const {
  SparseDerivativeStats stats = stats_;
  stats.point_dependent = pattern_.point_dependent;
  stats.num_cached_plans = static_cast<int>(jacobian_plans_.size() + hessian_plans_.size());
  stats.workspace_bytes = (inputs1_.capacity() + outputs1_.capacity()) * sizeof(Dual1) +
                          (inputs2_.capacity() + outputs2_.capacity()) * sizeof(Dual2);
  return stats;
}

}  // namespace moreau::internal

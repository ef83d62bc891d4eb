// The velocity-level problem of a lowered system (docs/fesd-formulation.md): consistent
// algebraic values for given statuses, event indicators, and the status decision at
// switching points (slow solution).

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include "lowered_block.hpp"
#include "moreau/core/error.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau {

std::vector<PairRole> LoweredSystem::RolesFor(const std::vector<bool>& a_zero) {
  std::vector<PairRole> roles;
  roles.reserve(a_zero.size());
  for (bool a : a_zero) roles.push_back(a ? PairRole::kAZero : PairRole::kBZero);
  return roles;
}

namespace {

// The storage type of a finished DerivativeMatrix (Matrix or SparseMatrix).
template <class M>
const M& Get(const DerivativeMatrix& d) {
  if constexpr (std::is_same_v<M, SparseMatrix>) {
    return d.sparse();
  } else {
    return d.dense();
  }
}

// Selects rows of candidate sources into an output: out row i = row source_row[i] of source
// source_id[i]. Built once per evaluation as sparse selection matrices (one per source), so
// that dense and sparse sources go through the same products.
class RowSelection {
 public:
  RowSelection(int num_sources, const std::vector<int>& source_rows_count)
      : entries_(static_cast<std::size_t>(num_sources)), source_rows_(source_rows_count) {}
  void Take(int source, int row) {
    entries_[static_cast<std::size_t>(source)].emplace_back(rows_++, row, 1.0);
  }
  int rows() const { return rows_; }
  // Selection matrix of one source (rows() x rows of the source).
  SparseMatrix Selector(int source) const {
    SparseMatrix s(rows_, source_rows_[static_cast<std::size_t>(source)]);
    const auto& e = entries_[static_cast<std::size_t>(source)];
    s.setFromTriplets(e.begin(), e.end());
    return s;
  }

 private:
  std::vector<std::vector<Eigen::Triplet<double, int>>> entries_;
  std::vector<int> source_rows_;
  int rows_ = 0;
};

// Candidate rows of the velocity-level problem (docs/fesd-formulation.md), for all rows of a
// kind at once: a value with its derivatives with respect to v, y, u and p.
template <class M>
struct Rows {
  Vector value;
  M d_v, d_y, d_u, d_p;
};

}  // namespace

template <class M>
static void AssembleVelocityLevel(const LoweredSystem& system, const PointEvaluation& e,
                                  const CurvatureTerms& curvature, const Vector& mask,
                                  const Vector& rates, const std::vector<PairRole>& roles,
                                  Derivatives derivatives, VelocityLevelEvaluation* out) {
  const bool with_y = derivatives != Derivatives::kNone;
  const bool all = derivatives == Derivatives::kAll;
  const int ng = system.num_equations(), np = system.num_pairs();
  const auto& pairs = system.pairs();
  const auto& differentiated = system.differentiated_equations();
  // Per pair: continuous side a (kA, kBoth) or b (kB); the other side is the jump side.
  Vector cont_a(np), cont_b(np);
  bool any_both = false;
  for (int k = 0; k < np; ++k) {
    const ContinuousSide side = pairs[static_cast<std::size_t>(k)].continuous;
    cont_a[k] = side != ContinuousSide::kB ? 1.0 : 0.0;
    cont_b[k] = 1.0 - cont_a[k];
    any_both |= side == ContinuousSide::kBoth;
  }
  const auto Da = cont_a.asDiagonal();
  const auto Db = cont_b.asDiagonal();
  const auto mask_diag = mask.asDiagonal();
  const M& F_z = Get<M>(e.F_z);
  // Rate of quantities X with derivatives x_y, x_z: X_y F + X_z v_c (curvature: the terms of
  // d/d(y, u, p) [X_y . F] with F held, given by the blocks).
  auto rate = [&](const M& x_y, const M& x_z, const DerivativeMatrix* c_y,
                  const DerivativeMatrix* c_u, const DerivativeMatrix* c_p) {
    Rows<M> r;
    r.value = x_y * e.F + x_z * rates;
    r.d_v = M(x_y * F_z) + M(x_z * mask_diag);
    if (with_y) {
      r.d_y = M(x_y * Get<M>(e.F_y));
      if (c_y != nullptr) r.d_y += Get<M>(*c_y);
    }
    if (all) {
      r.d_u = M(x_y * Get<M>(e.F_u));
      r.d_p = M(x_y * Get<M>(e.F_p));
      if (c_u != nullptr) r.d_u += Get<M>(*c_u);
      if (c_p != nullptr) r.d_p += Get<M>(*c_p);
    }
    return r;
  };
  auto value = [&](const Vector& x, const M& x_z, const M* x_y, const M* x_u, const M* x_p) {
    Rows<M> r;
    r.value = x;
    r.d_v = x_z;
    if (with_y) r.d_y = *x_y;
    if (all) {
      r.d_u = *x_u;
      r.d_p = *x_p;
    }
    return r;
  };
  // Sources: 0 G values, 1 G rates, 2 continuous-side rates, 3 jump-side values, 4 rates of b
  // (kBoth pairs: both sides continuous, the "jump" row is b's rate).
  std::vector<Rows<M>> sources(5);
  const M empty_y, empty_u, empty_p;
  if (ng > 0) {
    sources[0] = value(e.G, Get<M>(e.G_z), with_y ? &Get<M>(e.G_y) : &empty_y,
                       all ? &Get<M>(e.G_u) : &empty_u, all ? &Get<M>(e.G_p) : &empty_p);
    sources[1] = rate(Get<M>(e.G_y), Get<M>(e.G_z), with_y ? &curvature.equation_y : nullptr,
                      all ? &curvature.equation_u : nullptr, all ? &curvature.equation_p : nullptr);
  }
  if (np > 0) {
    const M x_y = M(Da * Get<M>(e.A_y)) + M(Db * Get<M>(e.B_y));
    const M x_z = M(Da * Get<M>(e.A_z)) + M(Db * Get<M>(e.B_z));
    sources[2] = rate(x_y, x_z, with_y ? &curvature.pair_y : nullptr,
                      all ? &curvature.pair_u : nullptr, all ? &curvature.pair_p : nullptr);
    const Vector j_value = Db * e.A + Da * e.B;
    const M j_z = M(Db * Get<M>(e.A_z)) + M(Da * Get<M>(e.B_z));
    M j_y, j_u, j_p;
    if (with_y) j_y = M(Db * Get<M>(e.A_y)) + M(Da * Get<M>(e.B_y));
    if (all) {
      j_u = M(Db * Get<M>(e.A_u)) + M(Da * Get<M>(e.B_u));
      j_p = M(Db * Get<M>(e.A_p)) + M(Da * Get<M>(e.B_p));
    }
    sources[3] = value(j_value, j_z, &j_y, &j_u, &j_p);
    if (any_both) sources[4] = rate(Get<M>(e.B_y), Get<M>(e.B_z), nullptr, nullptr, nullptr);
  }
  const std::vector<int> source_rows = {ng, ng, np, np, any_both ? np : 0};
  RowSelection equations(5, source_rows), a_rows(5, source_rows), b_rows(5, source_rows);
  for (int r = 0; r < ng; ++r)
    equations.Take(differentiated[static_cast<std::size_t>(r)] ? 1 : 0, r);
  for (int k = 0; k < np; ++k) {
    const ContinuousSide side = pairs[static_cast<std::size_t>(k)].continuous;
    const bool continuous_a = side != ContinuousSide::kB;
    const int jump_source = side == ContinuousSide::kBoth ? 4 : 3;
    const PairRole role = roles[static_cast<std::size_t>(k)];
    if (role == PairRole::kComplementary) {
      a_rows.Take(jump_source, k);
      b_rows.Take(2, k);
      continue;
    }
    // The kept side: its rate if continuous, its value if a jump variable.
    const bool keeps_a = role == PairRole::kAZero;
    equations.Take(keeps_a == continuous_a ? 2 : jump_source, k);
  }
  auto select = [&](const RowSelection& selection, Vector* values, DerivativeMatrix* dv,
                    DerivativeMatrix* dy, DerivativeMatrix* du, DerivativeMatrix* dp) {
    values->setZero(selection.rows());
    M v_sum, y_sum, u_sum, p_sum;
    bool first = true;
    for (int source = 0; source < 5; ++source) {
      if (source_rows[static_cast<std::size_t>(source)] == 0) continue;
      const Rows<M>& r = sources[static_cast<std::size_t>(source)];
      const SparseMatrix s = selection.Selector(source);
      if (s.nonZeros() == 0) continue;
      *values += s * r.value;
      if (first) {
        v_sum = M(s * r.d_v);
        if (with_y) y_sum = M(s * r.d_y);
        if (all) {
          u_sum = M(s * r.d_u);
          p_sum = M(s * r.d_p);
        }
        first = false;
      } else {
        v_sum += M(s * r.d_v);
        if (with_y) y_sum += M(s * r.d_y);
        if (all) {
          u_sum += M(s * r.d_u);
          p_sum += M(s * r.d_p);
        }
      }
    }
    const int rows = selection.rows();
    auto assign = [&](DerivativeMatrix* target, const M& m, int cols) {
      if (first) {
        target->SetZero(rows, cols, std::is_same_v<M, SparseMatrix>);
        target->Finalize();
      } else {
        target->SetZero(rows, cols, std::is_same_v<M, SparseMatrix>);
        target->Assign(m);
      }
    };
    assign(dv, v_sum, system.num_algebraic());
    if (with_y) assign(dy, y_sum, system.num_states());
    if (all) {
      assign(du, u_sum, system.num_inputs());
      assign(dp, p_sum, system.num_parameters());
    }
  };
  select(equations, &out->equations, &out->equations_v, &out->equations_y, &out->equations_u,
         &out->equations_p);
  select(a_rows, &out->a, &out->a_v, &out->a_y, &out->a_u, &out->a_p);
  select(b_rows, &out->b, &out->b_v, &out->b_y, &out->b_u, &out->b_p);
}

// Dense storage: every output row is computed on its own from one row of the point's blocks
// and written in place (coefficient-wise products, no temporaries). The systems that are
// stored dense are small (n_y + n_z <= kSparseStorageThreshold), where whole-matrix products
// through selection matrices cost many times the rows themselves (they dominated FESD's
// element cost on F1). The rows are those of the sparse path below, source by source.
static void AssembleVelocityLevelDense(const LoweredSystem& system, const PointEvaluation& e,
                                       const CurvatureTerms& curvature, const ConstVectorRef& v,
                                       const std::vector<PairRole>& roles, Derivatives derivatives,
                                       VelocityLevelEvaluation* out) {
  const bool with_y = derivatives != Derivatives::kNone;
  const bool all = derivatives == Derivatives::kAll;
  const int ny = system.num_states(), nz = system.num_algebraic();
  const int ng = system.num_equations(), np = system.num_pairs();
  const auto& pairs = system.pairs();
  const auto& differentiated = system.differentiated_equations();
  const auto& continuous = system.continuous_algebraic();
  int complementary = 0;
  for (PairRole role : roles) complementary += role == PairRole::kComplementary ? 1 : 0;

  // One output (equations, or the a or b sides of complementary pairs).
  struct Target {
    Vector* values;
    Matrix *dv, *dy, *du, *dp;
  };
  auto prepare = [&](int rows, Vector* values, DerivativeMatrix* dv, DerivativeMatrix* dy,
                     DerivativeMatrix* du, DerivativeMatrix* dp) {
    values->resize(rows);
    dv->SetZero(rows, nz, false);
    Target t{values, &dv->MutableDense(), nullptr, nullptr, nullptr};
    if (with_y) {
      dy->SetZero(rows, ny, false);
      t.dy = &dy->MutableDense();
    }
    if (all) {
      du->SetZero(rows, system.num_inputs(), false);
      dp->SetZero(rows, system.num_parameters(), false);
      t.du = &du->MutableDense();
      t.dp = &dp->MutableDense();
    }
    return t;
  };
  const Target equations = prepare(ng + np - complementary, &out->equations, &out->equations_v,
                                   &out->equations_y, &out->equations_u, &out->equations_p);
  const Target a_rows = prepare(complementary, &out->a, &out->a_v, &out->a_y, &out->a_u, &out->a_p);
  const Target b_rows = prepare(complementary, &out->b, &out->b_v, &out->b_y, &out->b_u, &out->b_p);

  const Matrix& F_z = e.F_z.dense();
  // product(j) = sum_l row(l) m(l, j), summed in order from l = 0 as Eigen's lazy product sums a
  // strided row (the same result); plain loops, whose set-up costs less than the
  // expression's on these small blocks.
  auto row_product = [](const auto& row, const Matrix& m, auto&& product) {
    const Eigen::Index n = m.rows();
    for (Eigen::Index j = 0; j < m.cols(); ++j) {
      const double* column = m.data() + j * n;
      double sum = n > 0 ? row[0] * column[0] : 0.0;
      for (Eigen::Index l = 1; l < n; ++l) sum += row[l] * column[l];
      product[j] = sum;
    }
  };
  // Rate of X along the flow, X_y F + X_z v_c (v_c: the continuous slots of v), from row r of
  // x_y, x_z; curvature rows c_* (null: none) complete d/d(y, u, p).
  auto rate_row = [&](const Target& t, int i, const DerivativeMatrix& x_y,
                      const DerivativeMatrix& x_z, int r, const DerivativeMatrix* c_y,
                      const DerivativeMatrix* c_u, const DerivativeMatrix* c_p) {
    const auto gradient = x_y.dense().row(r);
    const auto z_row = x_z.dense().row(r);
    double value = gradient.dot(e.F);
    auto dv = t.dv->row(i);
    row_product(gradient, F_z, dv);
    for (int j = 0; j < nz; ++j) {
      if (!continuous[static_cast<std::size_t>(j)]) continue;
      value += z_row[j] * v[j];
      dv[j] += z_row[j];
    }
    (*t.values)[i] = value;
    if (with_y) {
      row_product(gradient, e.F_y.dense(), t.dy->row(i));
      if (c_y != nullptr) t.dy->row(i) += c_y->dense().row(r);
    }
    if (all) {
      row_product(gradient, e.F_u.dense(), t.du->row(i));
      row_product(gradient, e.F_p.dense(), t.dp->row(i));
      if (c_u != nullptr) t.du->row(i) += c_u->dense().row(r);
      if (c_p != nullptr) t.dp->row(i) += c_p->dense().row(r);
    }
  };
  // A value X with its derivatives, row r.
  auto value_row = [&](const Target& t, int i, const Vector& x, const DerivativeMatrix& x_z,
                       const DerivativeMatrix& x_y, const DerivativeMatrix& x_u,
                       const DerivativeMatrix& x_p, int r) {
    (*t.values)[i] = x[r];
    t.dv->row(i) = x_z.dense().row(r);
    if (with_y) t.dy->row(i) = x_y.dense().row(r);
    if (all) {
      t.du->row(i) = x_u.dense().row(r);
      t.dp->row(i) = x_p.dense().row(r);
    }
  };

  // G rows: differentiated along the flow, or on values.
  for (int r = 0; r < ng; ++r) {
    if (differentiated[static_cast<std::size_t>(r)]) {
      rate_row(equations, r, e.G_y, e.G_z, r, with_y ? &curvature.equation_y : nullptr,
               all ? &curvature.equation_u : nullptr, all ? &curvature.equation_p : nullptr);
    } else {
      value_row(equations, r, e.G, e.G_z, e.G_y, e.G_u, e.G_p, r);
    }
  }
  int row = ng, pair_row = 0;
  for (int k = 0; k < np; ++k) {
    const ContinuousSide side = pairs[static_cast<std::size_t>(k)].continuous;
    const bool continuous_a = side != ContinuousSide::kB;
    // The rate of the continuous side (a for kA and kBoth, b for kB).
    auto continuous_rate = [&](const Target& t, int i) {
      rate_row(t, i, continuous_a ? e.A_y : e.B_y, continuous_a ? e.A_z : e.B_z, k,
               with_y ? &curvature.pair_y : nullptr, all ? &curvature.pair_u : nullptr,
               all ? &curvature.pair_p : nullptr);
    };
    // The jump side's value (kBoth pairs: both sides continuous, b's rate).
    auto jump = [&](const Target& t, int i) {
      if (side == ContinuousSide::kBoth) {
        rate_row(t, i, e.B_y, e.B_z, k, nullptr, nullptr, nullptr);
      } else if (continuous_a) {
        value_row(t, i, e.B, e.B_z, e.B_y, e.B_u, e.B_p, k);
      } else {
        value_row(t, i, e.A, e.A_z, e.A_y, e.A_u, e.A_p, k);
      }
    };
    const PairRole role = roles[static_cast<std::size_t>(k)];
    if (role == PairRole::kComplementary) {
      jump(a_rows, pair_row);
      continuous_rate(b_rows, pair_row);
      ++pair_row;
      continue;
    }
    // The kept side: its rate if continuous, its value if a jump variable.
    const bool keeps_a = role == PairRole::kAZero;
    if (keeps_a == continuous_a) {
      continuous_rate(equations, row++);
    } else {
      jump(equations, row++);
    }
  }
}

namespace {

// Compressed columns in kept vectors (capacity reused from call to call), for the
// allocation-free sparse assembly of the velocity-level values below.
struct Columns {
  int rows = 0, cols = 0;
  std::vector<int> outer, inner;
  std::vector<double> values;
  void Start(int r, int c) {
    rows = r;
    cols = c;
    outer.assign(static_cast<std::size_t>(c) + 1, 0);
    inner.clear();
    values.clear();
  }
  void Push(int i, double v) {
    inner.push_back(i);
    values.push_back(v);
  }
  void EndColumn(int j) { outer[static_cast<std::size_t>(j) + 1] = static_cast<int>(inner.size()); }
};

// A compressed-columns matrix to read: an Eigen one (compressed) or Columns.
struct ColumnsView {
  int rows, cols;
  const int *outer, *inner;
  const double* values;
  explicit ColumnsView(const SparseMatrix& m)
      : rows(static_cast<int>(m.rows())),
        cols(static_cast<int>(m.cols())),
        outer(m.outerIndexPtr()),
        inner(m.innerIndexPtr()),
        values(m.valuePtr()) {
    MOREAU_ASSERT(m.isCompressed(), "uncompressed derivative block");
  }
  explicit ColumnsView(const Columns& m)
      : rows(m.rows),
        cols(m.cols),
        outer(m.outer.data()),
        inner(m.inner.data()),
        values(m.values.data()) {}
};

// The workspace of AssembleVelocityValues (per thread: the assembly runs on the thread that
// solves, one at a time).
struct VelocityValuesWorkspace {
  Vector mask, rates;  // AssembleVelocityRows' continuity mask and rates (either assembly)
  Vector cont_a, cont_b;
  Columns x_y, x_z, product, scaled, scaled_b, d_v[5];
  Columns product_y, d_y[5];    // with derivatives in y: X_y F_y, and each source's rows
  Columns kept_y, kept_z;       // RateRows' X_y, X_z restricted to the rows an output takes
  std::vector<char> needed[5];  // per source row: taken by an output
  Vector value[5];
  std::vector<char> touched;  // product: rows met in the current column
  std::vector<double> accumulator;
  std::vector<int> met;
  std::vector<int> out_row;  // select: per source row, its row in the output (-1: none)
};
// Not inlined: the callers then hold the workspace by an ordinary pointer. Inlined, GCC
// specialized RateRows on the thread-local object and looked its address up
// (__tls_get_addr) in the innermost loop of the sparse product, a fifth of RateRows' time.
[[gnu::noinline]] VelocityValuesWorkspace& ThisThreadsVelocityValuesWorkspace() {
  thread_local VelocityValuesWorkspace workspace;
  return workspace;
}

// Eigen's sparse sum A + B of the same shape: the union of the patterns, a + b where both
// store an entry, a + 0 or 0 + b where one does (the same bits as Eigen's sum, which adds the
// zero: -0 becomes +0).
void SumColumns(const ColumnsView& a, const ColumnsView& b, Columns* out) {
  out->Start(a.rows, a.cols);
  for (int j = 0; j < a.cols; ++j) {
    int p = a.outer[j], q = b.outer[j];
    const int p_end = a.outer[j + 1], q_end = b.outer[j + 1];
    while (p < p_end || q < q_end) {
      if (p < p_end && q < q_end && a.inner[p] == b.inner[q]) {
        out->Push(a.inner[p], a.values[p] + b.values[q]);
        ++p;
        ++q;
      } else if (p < p_end && (q >= q_end || a.inner[p] < b.inner[q])) {
        out->Push(a.inner[p], a.values[p] + 0.0);
        ++p;
      } else {
        out->Push(b.inner[q], 0.0 + b.values[q]);
        ++q;
      }
    }
    out->EndColumn(j);
  }
}

// D A (rows scaled, `rows` true) or A D (columns scaled) for a diagonal D, every stored entry
// kept in its place, zero or not (Eigen's sparse-diagonal products, the same bits).
// With `keep`, only the entries of rows where keep[row] (the others dropped).
void Scaled(const ColumnsView& a, const Vector& d, bool rows, Columns* out,
            const std::vector<char>* keep = nullptr) {
  out->Start(a.rows, a.cols);
  for (int j = 0; j < a.cols; ++j) {
    for (int p = a.outer[j]; p < a.outer[j + 1]; ++p) {
      if (keep != nullptr && !(*keep)[static_cast<std::size_t>(a.inner[p])]) continue;
      out->Push(a.inner[p], a.values[p] * d[rows ? a.inner[p] : j]);
    }
    out->EndColumn(j);
  }
}

// D_a A + D_b B for diagonal D_a, D_b (Eigen's M(D_a A) + M(D_b B), the same bits), in the
// rows where keep[row] (the others empty: each row is its own).
void DiagonalSum(const Vector& da, const SparseMatrix& a, const Vector& db, const SparseMatrix& b,
                 const std::vector<char>& keep, VelocityValuesWorkspace* w, Columns* out) {
  Scaled(ColumnsView(a), da, true, &w->scaled, &keep);
  Scaled(ColumnsView(b), db, true, &w->scaled_b, &keep);
  SumColumns(ColumnsView(w->scaled), ColumnsView(w->scaled_b), out);
}

// X F_z by Eigen's conservative sparse product (per result column j, the rows i met through
// F_z's column j in order, each sum started by its first product: the same bits), rows
// increasing in each column.
void ProductColumns(const ColumnsView& x, const ColumnsView& f, VelocityValuesWorkspace* w,
                    Columns* out) {
  out->Start(x.rows, f.cols);
  w->touched.assign(static_cast<std::size_t>(x.rows), 0);
  w->accumulator.resize(static_cast<std::size_t>(x.rows));
  for (int j = 0; j < f.cols; ++j) {
    w->met.clear();
    for (int q = f.outer[j]; q < f.outer[j + 1]; ++q) {
      const double y = f.values[q];
      const int k = f.inner[q];
      for (int p = x.outer[k]; p < x.outer[k + 1]; ++p) {
        const auto i = static_cast<std::size_t>(x.inner[p]);
        if (!w->touched[i]) {
          w->touched[i] = 1;
          w->accumulator[i] = x.values[p] * y;
          w->met.push_back(x.inner[p]);
        } else {
          w->accumulator[i] += x.values[p] * y;
        }
      }
    }
    std::sort(w->met.begin(), w->met.end());
    for (int i : w->met) {
      out->Push(i, w->accumulator[static_cast<std::size_t>(i)]);
      w->touched[static_cast<std::size_t>(i)] = 0;
    }
    out->EndColumn(j);
  }
}

// The entries of `a` in the rows where keep[row] (the others dropped, rows keep their
// indices).
void KeepRows(const ColumnsView& a, const std::vector<char>& keep, Columns* out) {
  out->Start(a.rows, a.cols);
  for (int j = 0; j < a.cols; ++j) {
    for (int p = a.outer[j]; p < a.outer[j + 1]; ++p) {
      if (keep[static_cast<std::size_t>(a.inner[p])]) out->Push(a.inner[p], a.values[p]);
    }
    out->EndColumn(j);
  }
}

// The rate rows X_y F + X_z v_c and their derivative X_y F_z + X_z diag(mask); with `d_y`,
// also X_y F_y + C_y (C_y: the curvature rows `c_y`, null for none). AssembleVelocityLevel's
// `rate` without derivatives in u, p: the same bits.
//
// Every row of a product, sum or diagonal scaling below depends on the same row of X_y and
// X_z only (and a row's sums run in the same order whatever the other rows hold), so callers
// pass X_y and X_z restricted to the rows an output takes (KeepRows; FESD's velocity level takes
// the rates of active constraints, a few in a hundred of a crowd's working pairs): those rows
// come out bit for bit, the others empty.
void RateRows(const ColumnsView& x_y, const ColumnsView& x_z, const PointEvaluation& e,
              const Vector& mask, const Vector& rates, VelocityValuesWorkspace* w, Vector* value,
              Columns* d_v, const DerivativeMatrix* c_y = nullptr, Columns* d_y = nullptr) {
  // value = x_y F, then += x_z rates (Eigen assigns the first product and adds the second).
  value->setZero(x_y.rows);
  for (int k = 0; k < x_y.cols; ++k) {
    const double f_k = e.F[k];
    for (int p = x_y.outer[k]; p < x_y.outer[k + 1]; ++p)
      (*value)[x_y.inner[p]] += x_y.values[p] * f_k;
  }
  for (int j = 0; j < x_z.cols; ++j) {
    const double r_j = rates[j];
    for (int p = x_z.outer[j]; p < x_z.outer[j + 1]; ++p)
      (*value)[x_z.inner[p]] += x_z.values[p] * r_j;
  }
  ProductColumns(x_y, ColumnsView(e.F_z.sparse()), w, &w->product);
  Scaled(x_z, mask, false, &w->scaled);
  SumColumns(ColumnsView(w->product), ColumnsView(w->scaled), d_v);
  if (d_y == nullptr) return;
  // d_y = M(X_y F_y), then += C_y (Eigen's sparse sum: a + 0 where C_y stores nothing).
  if (c_y == nullptr) {
    ProductColumns(x_y, ColumnsView(e.F_y.sparse()), w, d_y);
  } else {
    ProductColumns(x_y, ColumnsView(e.F_y.sparse()), w, &w->product_y);
    SumColumns(ColumnsView(w->product_y), ColumnsView(c_y->sparse()), d_y);
  }
}

void CopyColumns(const SparseMatrix& m, Columns* out) {
  const ColumnsView v(m);
  out->Start(v.rows, v.cols);
  out->inner.assign(v.inner, v.inner + v.outer[v.cols]);
  out->values.assign(v.values, v.values + v.outer[v.cols]);
  for (int j = 0; j <= v.cols; ++j) out->outer[static_cast<std::size_t>(j)] = v.outer[j];
}

}  // namespace

// AssembleVelocityLevel<SparseMatrix> without derivatives in u, p (the velocity-level solves
// of status decisions, certificates and free sides, every element; with `curvature`, also the
// derivatives in y of the event's velocity rows in FESD's Newton Jacobian): the same rows and
// the same bits, computed in a kept workspace instead of through Eigen's sparse expressions,
// which allocate their temporaries on every call.
static void AssembleVelocityValues(const LoweredSystem& system, const PointEvaluation& e,
                                   const Vector& mask, const Vector& rates,
                                   const std::vector<PairRole>& roles,
                                   const CurvatureTerms* curvature, VelocityLevelEvaluation* out) {
  VelocityValuesWorkspace& w = ThisThreadsVelocityValuesWorkspace();
  const bool with_y = curvature != nullptr;
  const int ny = system.num_states();
  const int ng = system.num_equations(), np = system.num_pairs(), nz = system.num_algebraic();
  const auto& pairs = system.pairs();
  const auto& differentiated = system.differentiated_equations();
  w.cont_a.resize(np);
  w.cont_b.resize(np);
  bool any_both = false;
  for (int k = 0; k < np; ++k) {
    const ContinuousSide side = pairs[static_cast<std::size_t>(k)].continuous;
    w.cont_a[k] = side != ContinuousSide::kB ? 1.0 : 0.0;
    w.cont_b[k] = 1.0 - w.cont_a[k];
    any_both |= side == ContinuousSide::kBoth;
  }
  // The rows of each output, in AssembleVelocityLevel's order.
  auto equations = [&](auto&& f) {
    for (int r = 0; r < ng; ++r) f(differentiated[static_cast<std::size_t>(r)] ? 1 : 0, r);
    for (int k = 0; k < np; ++k) {
      const PairRole role = roles[static_cast<std::size_t>(k)];
      if (role == PairRole::kComplementary) continue;
      const ContinuousSide side = pairs[static_cast<std::size_t>(k)].continuous;
      const bool continuous_a = side != ContinuousSide::kB;
      const int jump_source = side == ContinuousSide::kBoth ? 4 : 3;
      f((role == PairRole::kAZero) == continuous_a ? 2 : jump_source, k);
    }
  };
  auto complementary = [&](bool a_side) {
    return [&, a_side](auto&& f) {
      for (int k = 0; k < np; ++k) {
        if (roles[static_cast<std::size_t>(k)] != PairRole::kComplementary) continue;
        const int jump_source =
            pairs[static_cast<std::size_t>(k)].continuous == ContinuousSide::kBoth ? 4 : 3;
        f(a_side ? jump_source : 2, k);
      }
    };
  };
  const int source_rows[5] = {ng, ng, np, np, any_both ? np : 0};
  for (int source = 0; source < 5; ++source)
    w.needed[source].assign(static_cast<std::size_t>(source_rows[source]), 0);
  auto need = [&](int source, int row) { w.needed[source][static_cast<std::size_t>(row)] = 1; };
  equations(need);
  complementary(true)(need);
  complementary(false)(need);
  // Sources as in AssembleVelocityLevel: 0 G values, 1 G rates, 2 continuous-side rates,
  // 3 jump-side values, 4 rates of b (kBoth pairs). The rate sources hold the rows an output
  // takes (RateRows).
  // (d_y of source s, or null without derivatives in y)
  auto d_y = [&](int source) { return with_y ? &w.d_y[source] : nullptr; };
  // Source s's rate rows from X_y, X_z over all its rows (curvature rows c_y, may be null).
  auto rate_rows = [&](int source, const SparseMatrix& x_y, const SparseMatrix& x_z,
                       const DerivativeMatrix* c_y) {
    KeepRows(ColumnsView(x_y), w.needed[source], &w.kept_y);
    KeepRows(ColumnsView(x_z), w.needed[source], &w.kept_z);
    RateRows(ColumnsView(w.kept_y), ColumnsView(w.kept_z), e, mask, rates, &w, &w.value[source],
             &w.d_v[source], c_y, d_y(source));
  };
  if (ng > 0) {
    w.value[0] = e.G;
    CopyColumns(e.G_z.sparse(), &w.d_v[0]);
    if (with_y) CopyColumns(e.G_y.sparse(), &w.d_y[0]);
    rate_rows(1, e.G_y.sparse(), e.G_z.sparse(), with_y ? &curvature->equation_y : nullptr);
  }
  if (np > 0) {
    DiagonalSum(w.cont_a, e.A_y.sparse(), w.cont_b, e.B_y.sparse(), w.needed[2], &w, &w.x_y);
    DiagonalSum(w.cont_a, e.A_z.sparse(), w.cont_b, e.B_z.sparse(), w.needed[2], &w, &w.x_z);
    // (x_y, x_z hold the rows taken already)
    RateRows(ColumnsView(w.x_y), ColumnsView(w.x_z), e, mask, rates, &w, &w.value[2], &w.d_v[2],
             with_y ? &curvature->pair_y : nullptr, d_y(2));
    Vector& j_value = w.value[3];
    j_value.resize(np);
    for (int k = 0; k < np; ++k) j_value[k] = w.cont_b[k] * e.A[k] + w.cont_a[k] * e.B[k];
    DiagonalSum(w.cont_b, e.A_z.sparse(), w.cont_a, e.B_z.sparse(), w.needed[3], &w, &w.d_v[3]);
    if (with_y) {
      DiagonalSum(w.cont_b, e.A_y.sparse(), w.cont_a, e.B_y.sparse(), w.needed[3], &w, &w.d_y[3]);
    }
    if (any_both) {
      rate_rows(4, e.B_y.sparse(), e.B_z.sparse(), nullptr);
    }
  }
  // One output: its rows (source, source row) in order; values 0 + the source's value (Eigen's
  // selection product adds to zeros), derivative rows copied, with + 0 on every entry when
  // more than one source contributes (Eigen's sum of the selections adds zeros).
  auto select = [&](auto&& for_each_row, Vector* values, DerivativeMatrix* dv,
                    DerivativeMatrix* dy) {
    int rows = 0;
    int sources_used = 0;
    bool used[5] = {false, false, false, false, false};
    for_each_row([&](int source, int) {
      ++rows;
      if (!used[source]) ++sources_used;
      used[source] = true;
    });
    values->setZero(rows);
    dv->SetZero(rows, nz, true);
    if (with_y) dy->SetZero(rows, ny, true);
    const bool add_zero = sources_used > 1;
    // The rows of derivative block d that this output takes (source rows mapped by out_row).
    auto take_rows = [&](const Columns& d, DerivativeMatrix* target) {
      for (int j = 0; j < d.cols; ++j) {
        for (int p = d.outer[static_cast<std::size_t>(j)];
             p < d.outer[static_cast<std::size_t>(j) + 1]; ++p) {
          const int i = w.out_row[static_cast<std::size_t>(d.inner[static_cast<std::size_t>(p)])];
          if (i < 0) continue;
          const double v = d.values[static_cast<std::size_t>(p)];
          target->Add(i, j, add_zero ? v + 0.0 : v);
        }
      }
    };
    for (int source = 0; source < 5; ++source) {
      if (!used[source] || source_rows[source] == 0) continue;
      w.out_row.assign(static_cast<std::size_t>(source_rows[source]), -1);
      int row = 0;
      for_each_row([&](int s, int r) {
        if (s == source) w.out_row[static_cast<std::size_t>(r)] = row;
        ++row;
      });
      const Vector& value = w.value[source];
      for (int r = 0; r < source_rows[source]; ++r) {
        const int i = w.out_row[static_cast<std::size_t>(r)];
        if (i >= 0) (*values)[i] += value[r];
      }
      take_rows(w.d_v[source], dv);
      if (with_y) take_rows(w.d_y[source], dy);
    }
    dv->Finalize();
    if (with_y) dy->Finalize();
  };
  select(equations, &out->equations, &out->equations_v, &out->equations_y);
  select(complementary(true), &out->a, &out->a_v, &out->a_y);
  select(complementary(false), &out->b, &out->b_v, &out->b_y);
}

// The velocity-level rows from the evaluation e of the system at (y, v) (velocity roles set,
// derivatives kStates, or kAll with Derivatives::kAll) and the curvature terms (with
// derivatives with respect to y).
static void AssembleVelocityRows(const LoweredSystem& system, const PointEvaluation& e,
                                 const CurvatureTerms& curvature, const ConstVectorRef& v,
                                 const std::vector<PairRole>& roles, Derivatives derivatives,
                                 VelocityLevelEvaluation* out) {
  if (!system.sparse()) {
    AssembleVelocityLevelDense(system, e, curvature, v, roles, derivatives, out);
    return;
  }
  // Rates of continuous variables sit in v's continuous slots; jump variables are values.
  // (In the thread's kept workspace: this runs for every velocity-level solve.)
  const int nz = system.num_algebraic();
  VelocityValuesWorkspace& w = ThisThreadsVelocityValuesWorkspace();
  Vector& mask = w.mask;
  mask.resize(nz);
  for (int i = 0; i < nz; ++i)
    mask[i] = system.continuous_algebraic()[static_cast<std::size_t>(i)] ? 1.0 : 0.0;
  Vector& rates = w.rates;
  rates.noalias() = mask.cwiseProduct(v);
  if (derivatives != Derivatives::kAll) {
    AssembleVelocityValues(system, e, mask, rates, roles,
                           derivatives == Derivatives::kStates ? &curvature : nullptr, out);
    return;
  }
  AssembleVelocityLevel<SparseMatrix>(system, e, curvature, mask, rates, roles, derivatives, out);
}

void LoweredSystem::EvaluateVelocityLevel(const ConstVectorRef& y, const ConstVectorRef& v,
                                          const std::vector<PairRole>& roles,
                                          Derivatives derivatives,
                                          VelocityLevelEvaluation* out) const {
  MOREAU_ASSERT(static_cast<int>(roles.size()) == num_pairs_, "wrong number of pair roles");
  const int ny = num_states_, ng = num_equations_;
  const int nu = scene_.num_inputs(), np = scene_.num_parameters();
  const bool with_y = derivatives != Derivatives::kNone;
  const bool all = derivatives == Derivatives::kAll;
  PointEvaluation& e = velocity_point_;
  EvaluatePoint(y, v, all ? Derivatives::kAll : Derivatives::kStates, &roles, &e);

  CurvatureTerms& curvature = curvature_;
  if (with_y) {
    curvature.pair_y.SetZero(num_pairs_, ny, sparse_);
    curvature.equation_y.SetZero(ng, ny, sparse_);
    curvature.pair_u.SetZero(num_pairs_, nu, sparse_);
    curvature.equation_u.SetZero(ng, nu, sparse_);
    curvature.pair_p.SetZero(num_pairs_, np, sparse_);
    curvature.equation_p.SetZero(ng, np, sparse_);
    internal::BlockContext context = MakeBlockContext();
    context.velocity_roles = &roles;
    context.velocity = &v;
    for (const auto& block : blocks_) block->AddCurvature(context, y, e.F, derivatives, &curvature);
    for (DerivativeMatrix* m : {&curvature.pair_y, &curvature.equation_y, &curvature.pair_u,
                                &curvature.equation_u, &curvature.pair_p, &curvature.equation_p}) {
      m->Finalize();
    }
  }
  AssembleVelocityRows(*this, e, curvature, v, roles, derivatives, out);
}

void LoweredSystem::EvaluateEventIndicators(const ConstVectorRef& y, const ConstVectorRef& v,
                                            const std::vector<bool>& a_zero,
                                            Derivatives derivatives,
                                            IndicatorEvaluation* out) const {
  MOREAU_ASSERT(static_cast<int>(a_zero.size()) == num_pairs_, "wrong number of statuses");
  out->values.setZero(num_pairs_);
  if (derivatives != Derivatives::kNone) {
    out->d_y.SetZero(num_pairs_, num_states_, sparse_);
    out->d_v.SetZero(num_pairs_, num_algebraic_, sparse_);
    out->d_u.SetZero(num_pairs_, scene_.num_inputs(), sparse_);
    out->d_p.SetZero(num_pairs_, scene_.num_parameters(), sparse_);
  }
  internal::BlockContext context = MakeBlockContext();
  for (const auto& block : blocks_) {
    block->EventIndicators(context, y, v, a_zero, derivatives, out);
  }
  if (derivatives != Derivatives::kNone) {
    for (DerivativeMatrix* m : {&out->d_y, &out->d_v, &out->d_u, &out->d_p}) m->Finalize();
  }
}

bool LoweredSystem::EvaluateEventIndicatorSlopes(const ConstVectorRef& y, const ConstVectorRef& v,
                                                 const std::vector<bool>& a_zero,
                                                 const ConstVectorRef& dy, Vector* values,
                                                 Vector* slopes) const {
  MOREAU_ASSERT(static_cast<int>(a_zero.size()) == num_pairs_, "wrong number of statuses");
  MOREAU_ASSERT(dy.size() == num_states_, "slope direction of the wrong size");
  values->setZero(num_pairs_);
  slopes->setZero(num_pairs_);
  internal::BlockContext context = MakeBlockContext();
  for (const auto& block : blocks_) {
    if (!block->EventIndicatorSlopes(context, y, v, a_zero, dy, *values, *slopes)) return false;
  }
  return true;
}

namespace {

// Velocity-level problem as a mixed complementarity system in v (roles fixed).
//
// With `linear` (systems affine in the algebraic unknowns, LoweredBlock::AffineInAlgebraic:
// Stewart, one-surface Heaviside, moving sets, one relay by time-freezing) the rows are exactly
// E(v) = M(y) v + q(y), and so are the pair sides a(v), b(v). The lowered system is then
// evaluated once, at the solve's initial point v0, and every value Newton asks for is
// E(v0) + M (v - v0), the values at v = 0 for the row scales included. Newton takes the same
// steps as on the evaluated rows (up to rounding) for the cost of one evaluation: a solve of
// fixed statuses is one factorization and one step, and a status decision's trial assignment
// without a solution no longer evaluates the system at each of its ~20 failing iterations.
class VelocitySystem final : public MixedComplementaritySystem {
 public:
  // affine_decided: the rows are affine in v for roles that decide every pair
  // (LoweredSystem::VelocityLevelIsAffineForDecidedRoles): with such roles the problem is the
  // same linear model, expanded at v0 for those roles (Reset without `point`).
  VelocitySystem(const LoweredSystem& system, bool linear, bool affine_decided)
      : system_(system), linear_(linear), affine_decided_(linear || affine_decided) {}
  // Fixed statuses (every pair decided).
  void SetStatuses(const std::vector<bool>& a_zero) {
    roles_.resize(a_zero.size());
    for (std::size_t k = 0; k < a_zero.size(); ++k) {
      roles_[k] = a_zero[k] ? PairRole::kAZero : PairRole::kBZero;
    }
  }
  void SetRoles(const std::vector<PairRole>& roles) { roles_ = roles; }
  // The state and the row scales; v0 is the point Newton starts from (the linear model's
  // expansion point). `point` (linear systems, may be null): the system's evaluation at
  // (y, v0) with derivatives, which then is the velocity-level evaluation at v0 (the blocks of
  // a linear system do not look at the velocity roles).
  void Reset(const Vector& y, const Vector& v0, const PointEvaluation* point = nullptr) {
    y_ = y;
    complementary_ = 0;
    for (PairRole role : roles_) complementary_ += role == PairRole::kComplementary ? 1 : 0;
    model_ = linear_ || (affine_decided_ && complementary_ == 0);
    MOREAU_ASSERT(point == nullptr || linear_, "Reset: a point expansion needs a linear level");
    // Row scales from the data: the rows are affine in v, and their values at v = 0 (the
    // free velocities grad c . f + c_t) set the size of their terms. Stiff dynamics (|f| ~
    // 1e5) make an absolute tolerance of 1e-12 unreachable in double precision; relative to
    // the data it is (hard-case suite: stiff set).
    if (linear_ && point != nullptr) {
      AssembleVelocityRows(system_, *point, no_curvature_, v0, roles_, Derivatives::kNone,
                           &evaluation_);
    } else if (model_) {
      system_.EvaluateVelocityLevel(y_, v0, roles_, Derivatives::kNone, &evaluation_);
    }
    Scale(v0);
  }

  // A linear level with dense storage whose roles_ decide every pair: Reset(y, v0, point) with
  // the rows taken from `rows`, the rows assembled from the same point at the same v0 for
  // `rows_roles` (roles_ except that pairs decided here may be complementary there: their
  // jump-side value rows are `rows.a`, their continuous-side rate rows `rows.b`). The dense
  // assembly computes every row on its own from the point, so the rows are those Reset would
  // assemble, bitwise; a status decision assembles them once for all its trials.
  void ResetFromRows(const Vector& y, const Vector& v0, const VelocityLevelEvaluation& rows,
                     const std::vector<PairRole>& rows_roles) {
    MOREAU_ASSERT(linear_ && !system_.sparse(), "ResetFromRows: linear dense levels only");
    y_ = y;
    complementary_ = 0;
    model_ = true;
    const int nz = system_.num_algebraic(), ng = system_.num_equations();
    const int rows_count = ng + static_cast<int>(roles_.size());
    const auto& pairs = system_.pairs();
    evaluation_.equations.resize(rows_count);
    evaluation_.equations_v.SetZero(rows_count, nz, false);
    Matrix& out = evaluation_.equations_v.MutableDense();
    const Matrix& equations_v = rows.equations_v.dense();
    const Matrix& a_v = rows.a_v.dense();
    const Matrix& b_v = rows.b_v.dense();
    // Row copies as plain strided loops (Eigen's row expressions cost more in set-up than the
    // nz entries they copy).
    const Eigen::Index out_rows = out.rows();
    auto copy_row = [&](const Matrix& source, int from_row, int to_row) {
      const Eigen::Index source_rows = source.rows();
      const double* from = source.data() + from_row;
      double* to = out.data() + to_row;
      for (int c = 0; c < nz; ++c) to[c * out_rows] = from[c * source_rows];
    };
    evaluation_.equations.head(ng) = rows.equations.head(ng);
    for (int r = 0; r < ng; ++r) copy_row(equations_v, r, r);
    int row = ng, source_row = ng, pair_row = 0;
    for (std::size_t k = 0; k < roles_.size(); ++k) {
      MOREAU_ASSERT(roles_[k] != PairRole::kComplementary, "ResetFromRows: undecided pair");
      if (rows_roles[k] != PairRole::kComplementary) {
        evaluation_.equations[row] = rows.equations[source_row];
        copy_row(equations_v, source_row++, row++);
        continue;
      }
      // The kept side: its rate if continuous (the b row), its value if a jump variable (a).
      const bool continuous_a = pairs[k].continuous != ContinuousSide::kB;
      const bool rate = (roles_[k] == PairRole::kAZero) == continuous_a;
      evaluation_.equations[row] = rate ? rows.b[pair_row] : rows.a[pair_row];
      copy_row(rate ? b_v : a_v, pair_row, row++);
      ++pair_row;
    }
    evaluation_.a.resize(0);
    evaluation_.b.resize(0);
    evaluation_.a_v.SetZero(0, nz, false);
    evaluation_.b_v.SetZero(0, nz, false);
    Scale(v0);
  }

 private:
  // Reset's row scales (and a linear level's expansion point).
  // The size of a row is that of its terms: its value at v = 0 and its change to the guess v0
  // (|q| + |M v0| for a row M v + q). The value at v = 0 alone misses the terms that come with
  // v: Stewart's rates are sums of theta_k times the mode fields, zero at theta = 0, of size
  // 1e5 for a scene in microseconds, where an absolute 1e-12 is below their round-off and the
  // decision fails ("no consistent continuation").
  void Scale(const Vector& v0) {
    if (model_) {
      v0_ = v0;
      step_ = -v0;  // the values at v = 0
      Model(step_, &zero_r_, &zero_a_, &zero_b_);
      guess_r_ = evaluation_.equations;  // the values at v0, the expansion point
      guess_a_ = evaluation_.a;
      guess_b_ = evaluation_.b;
    } else {
      system_.EvaluateVelocityLevel(y_, v0, roles_, Derivatives::kNone, &values_);
      guess_r_ = values_.equations;
      guess_a_ = values_.a;
      guess_b_ = values_.b;
      zeros_.setZero(num_unknowns());  // kept (no allocation per solve)
      system_.EvaluateVelocityLevel(y_, zeros_, roles_, Derivatives::kNone, &values_);
    }
    const Vector& r0 = model_ ? zero_r_ : values_.equations;
    const Vector& a0 = model_ ? zero_a_ : values_.a;
    const Vector& b0 = model_ ? zero_b_ : values_.b;
    scale_.resize(num_unknowns());
    for (int i = 0; i < num_equations(); ++i) {
      scale_[i] = 1.0 / (1.0 + std::fabs(r0[i]) + std::fabs(guess_r_[i] - r0[i]));
    }
    for (int k = 0; k < complementary_; ++k) {
      const double size = std::max(std::fabs(a0[k]) + std::fabs(guess_a_[k] - a0[k]),
                                   std::fabs(b0[k]) + std::fabs(guess_b_[k] - b0[k]));
      scale_[num_equations() + k] = 1.0 / (1.0 + size);
    }
    if (!scale_.allFinite()) scale_.setOnes();  // a non-finite model is reported by Evaluate
  }

 public:
  void ResidualScale(const Vector& /*v*/, Vector* scale) override { *scale = scale_; }

  // Newton's test with each row measured against the size of its terms at v itself,
  // |r_i(v)| + sum_j |dr_i/dv_j v_j| (a pair: the larger of its sides' sizes), instead of
  // Reset's sizes at v = 0 and at the guess. Those miss terms that only the solution has:
  // Stewart's rates theta_k times mode fields of 1e5 in a microsecond scene, from the guess
  // v = 0, sum to a small value with a round-off of 1e-12 relative to Reset's size, and Newton
  // stalls just above its tolerance (VelocitySolver::Solve asks this only then). The same
  // tolerance, relative to the sizes the solution's rows are computed from.
  bool HoldsRelativeToTermSizes(const Vector& v, double tolerance) {
    Vector r, a, b;
    if (!Evaluate(v, true, &r, &a, &b)) return false;  // (model: the Jacobian is Reset's)
    const Vector magnitude = v.cwiseAbs();
    auto sizes = [&](const DerivativeMatrix& jacobian, const Vector& values) {
      Vector size = values.cwiseAbs();
      if (jacobian.rows() == 0) return size;
      if (jacobian.is_sparse()) {
        const SparseMatrix& m = jacobian.sparse();
        for (int c = 0; c < m.outerSize(); ++c) {
          for (SparseMatrix::InnerIterator it(m, c); it; ++it) {
            size[it.row()] += std::fabs(it.value()) * magnitude[c];
          }
        }
      } else {
        size.noalias() += jacobian.dense().cwiseAbs() * magnitude;
      }
      return size;
    };
    const Vector size_r = sizes(evaluation_.equations_v, r);
    for (int i = 0; i < r.size(); ++i) {
      if (!(std::fabs(r[i]) <= tolerance * (1.0 + size_r[i]))) return false;
    }
    if (complementary_ == 0) return true;
    const Vector size_a = sizes(evaluation_.a_v, a), size_b = sizes(evaluation_.b_v, b);
    for (int k = 0; k < complementary_; ++k) {
      const double fischer_burmeister = a[k] + b[k] - std::hypot(a[k], b[k]);
      const double size = std::max(size_a[k], size_b[k]);
      if (!(std::fabs(fischer_burmeister) <= tolerance * (1.0 + size))) return false;
    }
    return true;
  }

  int num_unknowns() const override { return system_.num_algebraic(); }
  int num_equations() const override { return system_.num_algebraic() - complementary_; }
  int num_pairs() const override { return complementary_; }
  bool Evaluate(const Vector& v, bool with_jacobian, Vector* r, Vector* a, Vector* b) override {
    if (model_) {
      step_ = v - v0_;
      Model(step_, r, a, b);
    } else {
      VelocityLevelEvaluation& target = with_jacobian ? evaluation_ : values_;
      system_.EvaluateVelocityLevel(y_, v, roles_, Derivatives::kNone, &target);
      *r = target.equations;
      *a = target.a;
      *b = target.b;
    }
    return r->allFinite() && a->allFinite() && b->allFinite();
  }
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    jacobian->AddDerivative(0, 0, evaluation_.equations_v);
    if (complementary_ > 0) {
      jacobian->AddWeightedRows(num_equations(), 0, da, evaluation_.a_v);
      jacobian->AddWeightedRows(num_equations(), 0, db, evaluation_.b_v);
    }
  }
  double EstimatedJacobianNonzeros() const override {
    const VelocityLevelEvaluation& e = model_ ? evaluation_ : values_;
    return e.equations_v.NonZeros() + e.a_v.NonZeros() + e.b_v.NonZeros();
  }
  // The linear model of the current roles is used (set by Reset): a linear level, or one
  // affine for decided roles with every pair decided.
  bool model() const { return model_; }

 private:
  // The linear model's values at v0 + d.
  void Model(const Vector& d, Vector* r, Vector* a, Vector* b) const {
    *r = evaluation_.equations;
    *a = evaluation_.a;
    *b = evaluation_.b;
    evaluation_.equations_v.MultiplyAdd(d, *r);
    if (complementary_ > 0) {
      evaluation_.a_v.MultiplyAdd(d, *a);
      evaluation_.b_v.MultiplyAdd(d, *b);
    }
  }

  const LoweredSystem& system_;
  const bool linear_;
  const bool affine_decided_;
  bool model_ = false;
  Vector y_;
  std::vector<PairRole> roles_;
  int complementary_ = 0;
  // Nonlinear: the last with-Jacobian evaluation and values-only evaluations; linear: the
  // evaluation at v0.
  VelocityLevelEvaluation evaluation_, values_;
  Vector v0_, zero_r_, zero_a_, zero_b_;
  Vector zeros_;                        // nonlinear Scale: the point v = 0
  Vector guess_r_, guess_a_, guess_b_;  // Scale's values at the guess
  mutable Vector step_;
  Vector scale_;
  CurvatureTerms no_curvature_;  // (rows without derivatives with respect to y)
};

// Dense LU for dense storage; with sparse storage the automatic choice (KLU above
// kDenseSizeLimit unknowns: a crowd's contact Gram matrix J J^T is sparse).
SemismoothNewtonOptions VelocityNewtonOptions(bool sparse) {
  SemismoothNewtonOptions options;
  options.tolerance = 1e-12;
  options.max_iterations = 30;
  options.linear_solver = sparse ? LinearSolverKind::kAutomatic : LinearSolverKind::kDenseLu;
  return options;
}

// DecideStatuses without monotone candidates: every trial decides every pair, so its problem
// is a system of equations, and with a linear velocity level a linear one, which Newton solves
// in one step (a second removes round-off). A trial that has not converged after this many
// iterations is singular or inconsistent (Stewart's sliding trial at a transversal crossing
// whose fields have equal normal components: 23 iterations to stagnation before), and is not a
// continuation.
constexpr int kLinearTrialIterations = 3;

SemismoothNewtonOptions LinearTrialNewtonOptions(bool sparse) {
  SemismoothNewtonOptions options = VelocityNewtonOptions(sparse);
  options.max_iterations = kLinearTrialIterations;
  return options;
}

// A linear velocity-level problem of fixed statuses (every pair decided: no complementarity
// rows): Newton's first step (the same factorization and solve) without the rest of its
// machinery, accepted if the model's residual after it meets Newton's test; otherwise
// (singular matrix, test failed) the caller's Newton decides. Where it is accepted, Newton
// would have taken the same full step and stopped there (its line search takes a full step
// that meets the tolerance), so the solution is Newton's.
class LinearStep {
 public:
  bool Solve(VelocitySystem* problem, const SemismoothNewtonOptions& options, const Vector& v0,
             Vector* v) {
    const int n = problem->num_unknowns();
    const double tolerance = options.tolerance;
    problem->ResidualScale(v0, &scale_);
    problem->Evaluate(v0, true, &residual_, &a_, &b_);
    if (!residual_.allFinite()) return false;
    if (scale_.cwiseProduct(residual_).lpNorm<Eigen::Infinity>() <= tolerance) {
      *v = v0;  // Newton stops at the initial point (no minimum iterations)
      return true;
    }
    if (solver_ == nullptr || solver_size_ != n) {
      solver_ = MakeLinearSolver(options.linear_solver, n, problem->EstimatedJacobianNonzeros());
      solver_size_ = n;
    }
    jacobian_.Reset(n, solver_->wants_sparse());
    problem->AssembleJacobian(a_, b_, &jacobian_);  // no pairs: the weights are unused
    jacobian_.Finalize();
    if (solver_->Factorize(jacobian_) != FactorizationStatus::kSuccess) return false;
    step_ = -residual_;
    solver_->Solve(step_);
    trial_ = v0 + step_;
    if (!problem->Evaluate(trial_, true, &residual_, &a_, &b_)) return false;
    if (!(scale_.cwiseProduct(residual_).lpNorm<Eigen::Infinity>() <= tolerance)) return false;
    *v = trial_;
    return true;
  }

 private:
  Vector scale_, residual_, a_, b_, step_, trial_;
  SystemMatrix jacobian_;
  std::unique_ptr<LinearSolver> solver_;
  int solver_size_ = -1;
};

}  // namespace

namespace internal {

// SolveVelocityLevel's workspace: the system and its Newton solver are kept across solves (no
// allocation in steady state), and the last few solves are remembered: a solve at the same
// state, statuses, inputs and parameters returns the same solution instead of solving again.
// FESD asks for such repeats on every element (the last stage of a Radau IIA element is its
// end state: the end-of-element check and the stage certificates solve at the same point).
// The solution for fixed statuses is unique where the problem is regular, so only the
// starting guess is ignored, and a converged solve from another guess would differ by
// round-off within the Newton tolerance.
class VelocitySolver {
 public:
  // linear, affine_decided: LoweredSystem::VelocityLevelIsLinear and
  // VelocityLevelIsAffineForDecidedRoles.
  VelocitySolver(const LoweredSystem& system, bool linear, bool affine_decided)
      : problem_(system, linear, affine_decided),
        newton_(VelocityNewtonOptions(system.sparse())),
        linear_(linear),
        affine_decided_(affine_decided) {}

  // LoweredSystem::DecideStatuses' workspace, kept across decisions (FESD decides at t0 and at
  // every switch): the trials' problem, their Newton solvers (with their linear solvers) and
  // the evaluations, so that a decision allocates only for its result.
  struct Decision {
    Decision(const LoweredSystem& system, bool linear, bool affine_decided)
        : problem(system, linear, affine_decided),
          newton(VelocityNewtonOptions(system.sparse())),
          linear_trial_newton(LinearTrialNewtonOptions(system.sparse())) {}
    VelocitySystem problem;
    SemismoothNewton newton;               // every candidate complementary, and general trials
    SemismoothNewton linear_trial_newton;  // trials of an affine level without monotone ones
    LinearStep linear_step;                // the same trials' first step (LinearStep)
    Vector guess, solution, step, free_a, free_b, field;
    std::vector<PairRole> trial, block_roles;
    PointEvaluation at_y, point, expansion;
    VelocityLevelEvaluation evaluation;
    VelocityLevelEvaluation check;  // a linear level's checked rows at the guess
    CurvatureTerms no_curvature;    // (rows without derivatives with respect to y)
    // The consistent trials (the first num_valid entries are the current decision's; entries
    // are reused, so that a decision allocates only for its result).
    struct Valid {
      std::vector<PairRole> roles;
      Vector v;
      Vector velocity;
      int leaving = 0;  // candidates whose continuous side is free
    };
    std::vector<Valid> valid;
    std::vector<PairRole> roles;
    std::vector<int> candidates, enumerated, monotone, check_row;
  };
  // LoweredSystem::VelocityLevelIsLinear and VelocityLevelIsAffineForDecidedRoles of the
  // system it was made for.
  bool linear() const { return linear_; }
  bool affine_decided() const { return affine_decided_; }
  Decision& decision(const LoweredSystem& system) {
    if (decision_ == nullptr) {
      decision_ = std::make_unique<Decision>(system, linear_, affine_decided_);
    }
    return *decision_;
  }

  // point: the system's evaluation at (y, v0) with derivatives, or null.
  bool Solve(const LoweredSystem& system, const Vector& y, const std::vector<bool>& a_zero,
             const Vector& v0, const PointEvaluation* point, Vector* v) {
    for (const Entry& entry : entries_) {
      if (entry.Matches(system, y, a_zero)) {
        *v = entry.v;
        return entry.converged;
      }
    }
    problem_.SetStatuses(a_zero);
    problem_.Reset(y, v0, point);
    bool converged = false;
    // Every pair is decided: a level affine for decided roles is a linear system here.
    if (!problem_.model() || !linear_step_.Solve(&problem_, newton_.options(), v0, v)) {
      SemismoothNewtonResult& result = result_;
      newton_.Solve(problem_, v0, &result);
      *v = result.solution;
      converged = result.converged();
      if (!converged && (result.status == NewtonStatus::kLineSearchFailed ||
                         result.status == NewtonStatus::kStagnated)) {
        converged = problem_.HoldsRelativeToTermSizes(*v, newton_.options().tolerance);
      }
    } else {
      converged = true;
    }
    Entry& entry = entries_[next_];
    next_ = (next_ + 1) % kEntries;
    entry.y = y;
    entry.a_zero = a_zero;
    entry.inputs = system.inputs();
    entry.parameters = system.parameters();
    entry.v = *v;
    entry.converged = converged;
    entry.valid = true;
    return converged;
  }

 private:
  struct Entry {
    bool valid = false;
    Vector y, inputs, parameters, v;
    std::vector<bool> a_zero;
    bool converged = false;
    static bool Same(const Vector& a, const Vector& b) {
      return a.size() == b.size() && (a.array() == b.array()).all();
    }
    bool Matches(const LoweredSystem& system, const Vector& at, const std::vector<bool>& z) const {
      return valid && a_zero == z && Same(y, at) && Same(inputs, system.inputs()) &&
             Same(parameters, system.parameters());
    }
  };
  // Interior element ends of a group are checked before its certificates are computed.
  static constexpr int kEntries = 4;
  VelocitySystem problem_;
  SemismoothNewton newton_;
  SemismoothNewtonResult result_;  // kept: its storage serves every solve
  const bool linear_;
  const bool affine_decided_;
  Entry entries_[kEntries];
  int next_ = 0;
  LinearStep linear_step_;
  std::unique_ptr<Decision> decision_;
};

}  // namespace internal

bool LoweredSystem::VelocityLevelIsAffine(bool for_decided_roles) const {
  for (const auto& block : blocks_) {
    if (!(for_decided_roles ? block->AffineInAlgebraicForDecidedRoles()
                            : block->AffineInAlgebraic())) {
      return false;
    }
    // Time-freezing multiplies the physical-time blocks' F by the clock rate P(z), affine in z
    // if its block says so: the product is affine only where those blocks do not depend on z.
    if (clock_rate_block_ >= 0 && block->ScaledByClockRate() && block->num_algebraic() > 0) {
      return false;
    }
  }
  return true;
}

bool LoweredSystem::VelocityLevelIsLinear() const { return VelocityLevelIsAffine(false); }

bool LoweredSystem::VelocityLevelIsAffineForDecidedRoles() const {
  return VelocityLevelIsAffine(true);
}

internal::VelocitySolver& LoweredSystem::VelocitySolverOf() const {
  if (!velocity_solver_) {
    velocity_solver_ = std::make_shared<internal::VelocitySolver>(
        *this, VelocityLevelIsLinear(), VelocityLevelIsAffineForDecidedRoles());
  }
  return *velocity_solver_;
}

bool LoweredSystem::SolveVelocityLevel(const Vector& y, const std::vector<bool>& a_zero,
                                       const Vector& v0, Vector* v) const {
  if (num_algebraic_ == 0) {
    v->resize(0);
    return true;
  }
  return VelocitySolverOf().Solve(*this, y, a_zero, v0, nullptr, v);
}

bool LoweredSystem::SolveVelocityLevel(const Vector& y, const std::vector<bool>& a_zero,
                                       const Vector& v0, const Vector& z,
                                       const PointEvaluation& point, Vector* v) const {
  if (num_algebraic_ == 0) {
    v->resize(0);
    return true;
  }
  MOREAU_ASSERT(point.F_z.rows() == num_states_ && point.F_z.cols() == num_algebraic_,
                "SolveVelocityLevel: the point evaluation has no derivatives");
  internal::VelocitySolver& solver = VelocitySolverOf();
  if (!solver.linear()) return solver.Solve(*this, y, a_zero, v0, nullptr, v);
  return solver.Solve(*this, y, a_zero, z, &point, v);
}

StatusDecision LoweredSystem::DecideStatuses(const Vector& y, double candidate_tolerance) const {
  StatusDecision decision;
  decision.a_zero.assign(static_cast<std::size_t>(num_pairs_), false);
  if (num_pairs_ == 0) {
    decision.solved = true;
    decision.v.resize(0);
    return decision;
  }
  internal::VelocitySolver& solver = VelocitySolverOf();
  internal::VelocitySolver::Decision& workspace = solver.decision(*this);
  // Continuous sides at y from the index-1 consistent values (e.g. lambda = g - min g).
  Vector& guess = workspace.guess;
  InitialAlgebraicGuess(y, nullptr, &guess);
  PointEvaluation& at_y = workspace.at_y;
  Evaluate(y, guess, Derivatives::kNone, &at_y);
  std::vector<PairRole>& roles = workspace.roles;  // (every entry set below)
  roles.resize(static_cast<std::size_t>(num_pairs_));
  std::vector<int>& candidates = workspace.candidates;
  candidates.clear();
  for (int k = 0; k < num_pairs_; ++k) {
    const ContinuousSide side = pairs_[static_cast<std::size_t>(k)].continuous;
    const bool continuous_a = side != ContinuousSide::kB;
    const double continuous_value = continuous_a ? at_y.A[k] : at_y.B[k];
    // kBoth: b is continuous too (an index-1 multiplier, a function of the state).
    const double other_value =
        side == ContinuousSide::kBoth ? at_y.B[k] : std::numeric_limits<double>::infinity();
    if (std::min(continuous_value, other_value) < -candidate_tolerance) {
      std::ostringstream s;
      s << "pair '" << pairs_[static_cast<std::size_t>(k)].name
        << "' is violated at this state (continuous side "
        << std::min(continuous_value, other_value) << " < 0)";
      decision.message = s.str();
      return decision;
    }
    if (continuous_value > candidate_tolerance) {
      // The continuous side is positive: the jump side stays at zero.
      roles[static_cast<std::size_t>(k)] = continuous_a ? PairRole::kBZero : PairRole::kAZero;
    } else if (other_value > candidate_tolerance && side == ContinuousSide::kBoth) {
      // b is positive and continuous: it stays free, a stays at zero.
      roles[static_cast<std::size_t>(k)] = PairRole::kAZero;
    } else {
      roles[static_cast<std::size_t>(k)] = PairRole::kComplementary;
      candidates.push_back(k);
    }
  }
  decision.candidates = static_cast<int>(candidates.size());
  // Whether every block admits the roles (its structure, e.g. e^T theta = 1, rules out some).
  std::vector<PairRole>& block_roles = workspace.block_roles;  // (no allocation per trial)
  auto admitted_by_blocks = [&](const std::vector<PairRole>& r) {
    for (const auto& block : blocks_) {
      const auto first = r.begin() + block->layout.pair_offset;
      block_roles.assign(first, first + block->num_pairs());
      if (!block->AdmitsRoles(block_roles)) return false;
    }
    return true;
  };
  if (candidates.empty()) {
    // No pair is zero on its continuous side: the signs decide every status, and the
    // enumeration below would make one trial, the velocity level of these fixed statuses.
    // SolveVelocityLevel solves that same problem from the same guess with its kept solver
    // and workspace; should it fail, the enumeration decides as before.
    for (int k = 0; k < num_pairs_; ++k) {
      decision.a_zero[static_cast<std::size_t>(k)] =
          roles[static_cast<std::size_t>(k)] == PairRole::kAZero;
    }
    if (admitted_by_blocks(roles) && SolveVelocityLevel(y, decision.a_zero, guess, &decision.v)) {
      decision.solved = true;
      return decision;
    }
  }
  const int nx = scene_.num_states();
  SemismoothNewton& newton = workspace.newton;
  // Row of each complementary pair among the a, b rows of a velocity-level evaluation (they
  // follow the pair order).
  auto complementary_rows = [&](const std::vector<PairRole>& r, std::vector<int>* row) {
    row->assign(static_cast<std::size_t>(num_pairs_), -1);
    int next = 0;
    for (int k = 0; k < num_pairs_; ++k) {
      if (r[static_cast<std::size_t>(k)] == PairRole::kComplementary) {
        (*row)[static_cast<std::size_t>(k)] = next++;
      }
    }
  };
  // Candidates of monotone blocks (moving sets: the velocity-level problem in their
  // multipliers is an LCP with the symmetric positive semidefinite matrix J P J^T, so every
  // solution has the same velocity) need no enumeration: they stay complementary in every
  // trial, and the semismooth Newton solution decides them. Only the other candidates are
  // enumerated (their assignments can give different velocities: ambiguity).
  std::vector<int>& enumerated = workspace.enumerated;
  std::vector<int>& monotone = workspace.monotone;
  enumerated.clear();
  monotone.clear();
  for (int k : candidates) {
    const auto& block =
        *blocks_[static_cast<std::size_t>(pairs_[static_cast<std::size_t>(k)].block)];
    (block.MonotoneVelocityLevel() ? monotone : enumerated).push_back(k);
  }
  if (static_cast<int>(enumerated.size()) <= kMaxEnumeratedCandidates) candidates = enumerated;
  // Decides a complementary candidate from a solution: jump side zero (a <= b) means the
  // continuous side is free to leave zero. A degenerate pair (both sides zero to the
  // tolerance: a tangential departure) leaves, as the enumeration's tie-break between
  // continuations of equal velocity does.
  auto decide_complementary = [&](int k, const VelocityLevelEvaluation& e, int row) {
    const bool continuous_a = pairs_[static_cast<std::size_t>(k)].continuous != ContinuousSide::kB;
    const bool jump_zero = e.a[row] <= std::max(e.b[row], candidate_tolerance);
    decision.a_zero[static_cast<std::size_t>(k)] = jump_zero != continuous_a;
  };

  const bool linear = solver.linear();
  // One problem and evaluation workspace for all trials (SetRoles and Reset set every part
  // of the problem; the evaluations size and fill their outputs).
  VelocitySystem& system = workspace.problem;
  VelocityLevelEvaluation& e = workspace.evaluation;
  if (static_cast<int>(enumerated.size()) > kMaxEnumeratedCandidates) {
    system.SetRoles(roles);
    system.Reset(y, guess);
    const SemismoothNewtonResult result = newton.Solve(system, guess);
    if (!result.converged()) {
      decision.message = "velocity-level complementarity problem: " + result.message;
      return decision;
    }
    decision.v = result.solution;
    EvaluateVelocityLevel(y, decision.v, roles, Derivatives::kNone, &e);
    for (int k = 0; k < num_pairs_; ++k)
      decision.a_zero[static_cast<std::size_t>(k)] =
          roles[static_cast<std::size_t>(k)] == PairRole::kAZero;
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      decide_complementary(candidates[i], e, static_cast<int>(i));
    }
    decision.solved = true;
    return decision;
  }
  for (int k : monotone) roles[static_cast<std::size_t>(k)] = PairRole::kComplementary;
  // Without monotone candidates every trial decides every pair, so that a level affine for
  // decided roles (a linear one, or index-1 complementarity) makes every trial a linear system
  // (kLinearTrialIterations), solved on its model expanded at the guess (Reset).
  const bool linear_trials = monotone.empty() && (linear || solver.affine_decided());
  SemismoothNewton& trial_newton = linear_trials ? workspace.linear_trial_newton : workspace.newton;

  // Enumerate: every candidate keeps either its jump side at zero (the continuous side may
  // leave zero) or its continuous side's rate at zero (it stays at zero).
  using Valid = internal::VelocitySolver::Decision::Valid;
  std::vector<Valid>& valid = workspace.valid;
  std::size_t num_valid = 0;
  auto add_valid = [&](const std::vector<PairRole>& trial, const Vector& v, const auto& velocity,
                       int leaving) {
    if (valid.size() == num_valid) valid.emplace_back();
    Valid& entry = valid[num_valid++];
    entry.roles = trial;
    entry.v = v;
    entry.velocity = velocity;
    entry.leaving = leaving;
  };
  const double sign_tolerance = candidate_tolerance;
  PointEvaluation& point = workspace.point;
  // A linear velocity level is the expansion of one evaluation at (y, guess), which the blocks
  // make without looking at the roles: evaluated once for all trials. So are the rows the
  // trials are checked on (every candidate complementary: the roles themselves), and a
  // trial's free sides and state derivative at its solution are read off that expansion,
  // E(v) = E(guess) + E_v (v - guess) and F(v) = F(guess) + F_z (v - guess): the linear model
  // the trial was solved on, instead of an evaluation of the system with derivatives per
  // trial (equal up to round-off: the rows and F are affine in v).
  PointEvaluation& expansion = workspace.expansion;
  VelocityLevelEvaluation& check_rows = workspace.check;
  if (linear) {
    Evaluate(y, guess, Derivatives::kStates, &expansion);
    AssembleVelocityRows(*this, expansion, workspace.no_curvature, guess, roles, Derivatives::kNone,
                         &check_rows);
  }
  // Every trial's check has the roles `roles` (its candidates complementary again).
  std::vector<int>& check_row = workspace.check_row;
  complementary_rows(roles, &check_row);
  Vector& solution = workspace.solution;
  for (unsigned mask = 0; mask < (1u << candidates.size()); ++mask) {
    std::vector<PairRole>& trial = workspace.trial;
    trial = roles;
    int leaving = 0;
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      const int k = candidates[i];
      const bool continuous_a =
          pairs_[static_cast<std::size_t>(k)].continuous != ContinuousSide::kB;
      const bool jump_zero = (mask >> i) & 1u;
      leaving += jump_zero ? 1 : 0;
      // Keeping the jump side zero means keeping the side that is not continuous.
      trial[static_cast<std::size_t>(k)] =
          (jump_zero == continuous_a) ? PairRole::kBZero : PairRole::kAZero;
    }
    if (!admitted_by_blocks(trial)) continue;
    system.SetRoles(trial);
    if (linear && monotone.empty() && !sparse_) {
      system.ResetFromRows(y, guess, check_rows, roles);  // the rows assembled once
    } else {
      system.Reset(y, guess, linear ? &expansion : nullptr);
    }
    // Without monotone candidates a linear trial is a linear system: its first Newton step,
    // where it meets the tolerance, is the solution Newton returns (LinearStep).
    if (!(linear_trials &&
          workspace.linear_step.Solve(&system, trial_newton.options(), guess, &solution))) {
      SemismoothNewtonResult result = trial_newton.Solve(system, guess);
      if (!result.converged()) continue;
      solution = std::move(result.solution);
    }
    // The free side of every candidate must be nonnegative.
    const Vector* free_a = &workspace.free_a;
    const Vector* free_b = &workspace.free_b;
    if (linear) {
      workspace.step = solution - guess;
      workspace.free_a = check_rows.a;
      workspace.free_b = check_rows.b;
      check_rows.a_v.MultiplyAdd(workspace.step, workspace.free_a);
      check_rows.b_v.MultiplyAdd(workspace.step, workspace.free_b);
    } else {
      EvaluateVelocityLevel(y, solution, roles, Derivatives::kNone, &e);
      free_a = &e.a;
      free_b = &e.b;
    }
    bool ok = true;
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      const bool jump_zero = (mask >> i) & 1u;
      const int r = check_row[static_cast<std::size_t>(candidates[i])];
      const double free = jump_zero ? (*free_b)[r] : (*free_a)[r];
      ok &= free >= -sign_tolerance;
    }
    if (!ok) continue;
    if (linear) {
      workspace.field = expansion.F;
      expansion.F_z.MultiplyAdd(workspace.step, workspace.field);
      add_valid(trial, solution, workspace.field.head(nx), leaving);
    } else {
      EvaluatePoint(y, solution, Derivatives::kNone, &trial, &point);
      add_valid(trial, solution, point.F.head(nx), leaving);
    }
  }
  if (num_valid == 0) {
    decision.message = "no consistent continuation of the " + std::to_string(candidates.size()) +
                       " pairs that are zero at this state";
    return decision;
  }
  // Slow solution: least velocity norm; among equal velocities, the most pairs leaving zero.
  std::size_t best = 0;
  for (std::size_t i = 1; i < num_valid; ++i) {
    const double difference = (valid[i].velocity - valid[best].velocity).norm();
    const double scale = 1.0 + valid[best].velocity.norm();
    if (difference <= 1e-9 * scale) {
      if (valid[i].leaving > valid[best].leaving) best = i;
    } else if (valid[i].velocity.norm() < valid[best].velocity.norm()) {
      best = i;
    }
  }
  for (std::size_t i = 0; i < num_valid; ++i) {
    const Valid& other = valid[i];
    if ((other.velocity - valid[best].velocity).norm() >
        1e-9 * (1.0 + valid[best].velocity.norm())) {
      decision.ambiguous = true;
    }
  }
  if (decision.ambiguous) {
    std::ostringstream s;
    s << num_valid << " consistent continuations with different velocities; the slow one "
      << "(least |x'| = " << valid[best].velocity.norm() << ") is taken";
    decision.message = s.str();
  }
  decision.v = valid[best].v;
  for (int k = 0; k < num_pairs_; ++k) {
    decision.a_zero[static_cast<std::size_t>(k)] =
        valid[best].roles[static_cast<std::size_t>(k)] == PairRole::kAZero;
  }
  if (!monotone.empty()) {
    EvaluateVelocityLevel(y, decision.v, valid[best].roles, Derivatives::kNone, &e);
    std::vector<int> row;
    complementary_rows(valid[best].roles, &row);
    for (int k : monotone) decide_complementary(k, e, row[static_cast<std::size_t>(k)]);
  }
  decision.solved = true;
  return decision;
}

}  // namespace moreau

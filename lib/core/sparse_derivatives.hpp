#pragma once
// Sparse exact derivatives of automatically differentiated functions (TypedFunction):
// sparsity detection with SparsityTracer, distance-2 column colouring, compressed forward mode
// with Dual1 (Jacobians) and Dual2 (weighted Hessians, per-output direct recovery).
// docs/sparse-derivatives.md describes the method, its costs and its references.

#include <cstdint>
#include <memory>
#include <vector>

#include "moreau/core/smooth_function.hpp"

namespace moreau::internal {

// Structural derivative patterns of one function for given argument sizes, over its inputs
// numbered x | u | t | p (input nx + nu is t).
struct SparsityPattern {
  int nx = -1, nu = -1, np = -1;
  int num_inputs = 0;
  // The traced evaluation inspected a traced value (SparsityTape::value_dependent).
  bool point_dependent = false;
  // Output k depends on the inputs jac_inputs[jac_start[k] .. jac_start[k + 1]) (sorted).
  std::vector<int> jac_start, jac_inputs;
  // Second-derivative pairs (hess_first[e], hess_second[e]), first <= second, of output k for
  // e in [hess_start[k], hess_start[k + 1]) (sorted, unique).
  std::vector<int> hess_start, hess_first, hess_second;

  bool SameSizes(int x, int u, int p) const { return nx == x && nu == u && np == p; }
};

// Traces `function` at (x, u, t, p) with SparsityTracer and derives its patterns.
SparsityPattern DetectSparsity(TypedFunction* function, const ConstVectorRef& x,
                               const ConstVectorRef& u, double t, const ConstVectorRef& p);

// into := into u other (same sizes). Returns true if entries were added.
bool MergePattern(const SparsityPattern& other, SparsityPattern* into);

// The sparse derivative machinery of one TypedFunction: its pattern (detected at the first
// call), the patterns and colourings of the (wrt, rows) combinations in use (cached, least
// recently used evicted), and the Dual1/Dual2 workspaces. No allocation in steady state.
class SparseDerivatives {
 public:
  SparseDerivatives();
  ~SparseDerivatives();
  SparseDerivatives(const SparseDerivatives&) = delete;
  SparseDerivatives& operator=(const SparseDerivatives&) = delete;

  void Jacobian(TypedFunction* function, const ConstVectorRef& x, const ConstVectorRef& u, double t,
                const ConstVectorRef& p, Wrt wrt, Vector* out, SparseMatrix* jac,
                const std::vector<int>* rows);
  void WeightedHessian(TypedFunction* function, const ConstVectorRef& x, const ConstVectorRef& u,
                       double t, const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                       SparseMatrix* hess, const std::vector<int>* rows);
  void HessianDirection(TypedFunction* function, const ConstVectorRef& x,
                        const ConstVectorRef& u, double t, const ConstVectorRef& p, Wrt wrt,
                        const ConstVectorRef& direction, SparseMatrix* rows_matrix,
                        const std::vector<int>* rows);
  SparseDerivativeStats stats() const;

  // Least recently used plans beyond this number are dropped (active sets change over a run;
  // a plan costs O(entries) memory).
  static constexpr int kMaxPlansPerKind = 8;

 private:
  struct JacobianPlan;
  struct HessianPlan;

  // Detects the pattern at the first call, when the argument sizes change, and at every call
  // for point-dependent functions (then merged into the stored pattern, plans dropped if it
  // grew).
  void UpdatePattern(TypedFunction* function, const ConstVectorRef& x, const ConstVectorRef& u,
                     double t, const ConstVectorRef& p);
  JacobianPlan& FindJacobianPlan(const TypedFunction& function, Wrt wrt,
                                 const std::vector<int>* rows);
  HessianPlan& FindHessianPlan(const TypedFunction& function, Wrt wrt,
                               const std::vector<int>* rows);
  // Constant Dual1/Dual2 copies of all inputs (x | u | t | p).
  void FillInputs1(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                   const ConstVectorRef& p);
  void FillInputs2(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                   const ConstVectorRef& p);

  SparsityPattern pattern_;
  std::vector<std::unique_ptr<JacobianPlan>> jacobian_plans_;
  std::vector<std::unique_ptr<HessianPlan>> hessian_plans_;
  std::uint64_t clock_ = 0;  // for least-recently-used eviction

  // Workspaces.
  std::vector<double> input_values_;
  std::vector<Dual1> inputs1_, outputs1_;
  std::vector<Dual2> inputs2_, outputs2_;
  std::vector<int> input_mark_, color_mark_, compact_color_, seeded_, active_outputs_;
  std::vector<int> used_colors_;
  std::vector<int> seeded_column_;  // HessianDirection: the column of every seeded input
  std::vector<char> needed_chunk_pairs_;
  int mark_stamp_ = 0;

  SparseDerivativeStats stats_;
};

}  // namespace moreau::internal

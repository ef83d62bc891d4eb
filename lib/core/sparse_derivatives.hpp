#pragma once
// Sparse exact derivatives of automatically differentiated functions (TypedFunction):
// sparsity detection with SparsityTracer, distance-2 column colouring, compressed forward mode
// with Dual1 (Jacobians) and Dual2 (weighted Hessians, per-output direct recovery).
// docs/sparse-derivatives.md describes the method, its costs and its references.

#include <cstdint>
#include <memory>
#include <mutex>
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
  // |a| of a traced value (SparsityTape::piecewise).
  bool piecewise = false;
  // Output k depends on the inputs jac_inputs[jac_start[k] .. jac_start[k + 1]) (sorted).
  std::vector<int> jac_start, jac_inputs;
  // Second-derivative pairs (hess_first[e], hess_second[e]), first <= second, of output k for
  // e in [hess_start[k], hess_start[k + 1]) (sorted, unique).
  std::vector<int> hess_start, hess_first, hess_second;

  bool SameSizes(int x, int u, int p) const { return nx == x && nu == u && np == p; }
};

// The selected blocks of `wrt` as bits (x 1, u 2, t 4, p 8).
inline unsigned WrtBits(Wrt wrt) {
  return (wrt.x ? 1u : 0u) | (wrt.u ? 2u : 0u) | (wrt.t ? 4u : 0u) | (wrt.p ? 8u : 0u);
}

// What a pattern proves about a function's derivatives, per argument block (0 = x, 1 = u,
// 2 = t, 3 = p): couples[a][b] if some output has a second-derivative pair of an input of block
// a and one of block b. Patterns that depend on the point prove nothing.
struct FunctionStructure {
  int nx = -1, nu = -1, np = -1;
  bool point_dependent = true;
  bool piecewise = false;
  bool couples[4][4] = {};
  // Bit WrtBits(wrt) set: HessianZero(wrt) (made by AnalyzeStructure).
  unsigned hessian_zero = 0;
  // Bit WrtBits(wrt) set: no output depends on an input of the selected blocks.
  unsigned jacobian_zero = 0;

  bool SameSizes(int x, int u, int p) const { return nx == x && nu == u && np == p; }
  // No second derivative among the selected blocks: weighted Hessians and second derivatives
  // along directions with respect to them are zero.
  bool HessianZero(Wrt wrt) const { return (hessian_zero >> WrtBits(wrt)) & 1u; }
  // The first derivatives with respect to the selected blocks do not depend on the values of
  // the selected inputs (affine in them, no |.|): for fixed values of the other inputs the
  // Jacobian is one constant matrix, bit for bit (forward mode then multiplies the seeds by
  // the same constants at every point).
  bool JacobianConstant(Wrt wrt) const { return HessianZero(wrt) && !piecewise; }
  // The outputs do not depend on the selected inputs (a circuit's constant input matrix in x
  // and t): for fixed values of the other inputs the values are one constant vector too.
  bool JacobianZero(Wrt wrt) const {
    return JacobianConstant(wrt) && ((jacobian_zero >> WrtBits(wrt)) & 1u) != 0;
  }
};
FunctionStructure AnalyzeStructure(const SparsityPattern& pattern);

// Traces `function` at (x, u, t, p) with SparsityTracer and derives its patterns.
SparsityPattern DetectSparsity(TypedFunction* function, const ConstVectorRef& x,
                               const ConstVectorRef& u, double t, const ConstVectorRef& p);

// into := into u other (same sizes). Returns true if entries were added.
bool MergePattern(const SparsityPattern& other, SparsityPattern* into);

// A function's pattern for one set of argument sizes, and what it proves.
struct AnalyzedPattern {
  SparsityPattern pattern;
  FunctionStructure structure;
};

// The analysis of one function, shared by a function object and its clones (copies of a scene,
// of a lowered system, of an integrator's workspace all evaluate the same code): its traced
// pattern per argument sizes, detected by the first object that needs it. Thread-safe: clones
// may be used from different threads. A point-dependent pattern is the one of the first point
// traced (its structure proves nothing; SparseDerivatives traces such functions at every call).
class FunctionAnalysis {
 public:
  // The entry for the sizes of x, u, p; traces `function` at (x, u, t, p) if there is none
  // yet (*detected then true).
  std::shared_ptr<const AnalyzedPattern> Find(TypedFunction* function, const ConstVectorRef& x,
                                              const ConstVectorRef& u, double t,
                                              const ConstVectorRef& p, bool* detected);

 private:
  std::mutex mutex_;
  std::vector<std::shared_ptr<const AnalyzedPattern>> entries_;
};

// The sparse derivative machinery of one TypedFunction: its pattern (detected at the first
// call), the patterns and colourings of the (wrt, rows) combinations in use (cached, least
// recently used evicted), and the Dual1/Dual2 workspaces. No allocation in steady state.
class ThreadPool;

class SparseDerivatives {
 public:
  SparseDerivatives();
  ~SparseDerivatives();
  SparseDerivatives(const SparseDerivatives&) = delete;
  SparseDerivatives& operator=(const SparseDerivatives&) = delete;

  // `pool` (may be null): the threads a function made of blocks may use for its Jacobian.
  void Jacobian(TypedFunction* function, const ConstVectorRef& x, const ConstVectorRef& u, double t,
                const ConstVectorRef& p, Wrt wrt, Vector* out, SparseMatrix* jac,
                const std::vector<int>* rows, ThreadPool* pool = nullptr);
  void WeightedHessian(TypedFunction* function, const ConstVectorRef& x, const ConstVectorRef& u,
                       double t, const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& weights,
                       SparseMatrix* hess, const std::vector<int>* rows);
  void HessianDirection(TypedFunction* function, const ConstVectorRef& x, const ConstVectorRef& u,
                        double t, const ConstVectorRef& p, Wrt wrt, const ConstVectorRef& direction,
                        SparseMatrix* rows_matrix, const std::vector<int>* rows);
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
  // Functions made of blocks (TypedFunction::block_outputs() > 0, a pattern that does not
  // depend on the point): per block forward mode with one direction per input of the block
  // (chunks of 16 beyond), only the blocks the plan's rows or nonzero weights need. Jacobians
  // run on the pool's threads, each block's entries written to their own places; second
  // derivatives (Dual2 inputs are 2.3 kB each: one array, one thread) run in block order.
  bool UseBlocks(const TypedFunction& function) const;
  // Block Jacobians with fewer than kParallelMinBlocks blocks (thread_pool.hpp) run on the
  // calling thread.
  void BlockJacobian(TypedFunction* function, const JacobianPlan& plan, Vector* out, double* values,
                     ThreadPool* pool);
  void BlockWeightedHessian(TypedFunction* function, const HessianPlan& plan,
                            const ConstVectorRef& x, const ConstVectorRef& u, double t,
                            const ConstVectorRef& p, const ConstVectorRef& weights, double* values);
  void BlockHessianDirection(TypedFunction* function, const HessianPlan& plan,
                             const ConstVectorRef& direction, double* values);
  // Per-block plan data (made with the plans of functions made of blocks).
  void AddJacobianBlocks(const TypedFunction& function, const std::vector<int>& selected,
                         const std::vector<int>& row_start, const std::vector<int>& row_column,
                         const std::vector<int>& position, const std::vector<int>& column_of,
                         JacobianPlan* plan) const;
  void AddHessianBlocks(const TypedFunction& function, HessianPlan* plan) const;

  // Constant Dual1/Dual2 copies of all inputs (x | u | t | p).
  void FillInputs1(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                   const ConstVectorRef& p);
  // input_values_ = x | u | t | p.
  void GatherInputValues(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                         const ConstVectorRef& p);
  // *inputs for a block Jacobian with respect to `wrt_bits`, from input_values_: every entry
  // unless `clean` (no seeds left in *inputs) and of the right size, else only the inputs of
  // the argument blocks not differentiated (read as constants). The others are seeded from
  // input_values_ by each block that depends on them, and the pattern of a function made of
  // blocks does not depend on the point (UseBlocks), so an output asked for depends on no
  // other input: their entries may keep earlier values. A fill per evaluation wrote one cache
  // line per input (the crowd of 10^4: 20000, about 3% of its run).
  void FillBlockInputs1(unsigned wrt_bits, std::vector<Dual1>* inputs, bool clean) const;
  void FillInputs2(const ConstVectorRef& x, const ConstVectorRef& u, double t,
                   const ConstVectorRef& p);

  SparsityPattern pattern_;
  std::vector<std::unique_ptr<JacobianPlan>> jacobian_plans_;
  std::vector<std::unique_ptr<HessianPlan>> hessian_plans_;
  std::uint64_t clock_ = 0;  // for least-recently-used eviction

  // Workspaces.
  std::vector<double> input_values_;
  std::vector<Dual1> inputs1_, outputs1_;
  // Every entry of inputs1_ is a constant (no seeds left: false while an evaluation seeds,
  // and after one that threw).
  bool inputs1_clean_ = false;
  std::vector<Dual2> inputs2_, outputs2_;
  std::vector<int> input_mark_, color_mark_, compact_color_, seeded_, active_outputs_;
  std::vector<int> used_colors_;
  std::vector<int> seeded_column_;  // HessianDirection: the column of every seeded input
  std::vector<char> needed_chunk_pairs_;
  int mark_stamp_ = 0;
  // Block evaluations: per thread (thread 0: inputs1_) the Dual1 inputs and a block's outputs.
  struct BlockWorkspace {
    std::vector<Dual1> inputs1, outputs1;
    bool has_inputs = false;  // inputs1 is ready for this call (workers' copies)
    bool clean = false;       // as inputs1_clean_, for inputs1
  };
  std::vector<BlockWorkspace> block_workspaces_;
  std::vector<Dual2> block_outputs2_;

  SparseDerivativeStats stats_;
};

}  // namespace moreau::internal

#pragma once
/// @file
/// LoweredSystem: a scene lowered to an autonomous dynamic complementarity system (DCS)
///
///   y' = F(y, z),   0 = G(y, z),   0 <= A_k(y, z) ⟂ B_k(y, z) >= 0  (k = 1..n_pairs),
///
/// in the state y = (x, internal states, clock) and the algebraic unknowns z, with
/// n_z = n_G + n_pairs so that every collocation stage is square. The clock is the last
/// state; it carries physical time (clock' = 1, or 0 while time is frozen), so F, G, A and B
/// never depend on the integration variable explicitly. Parameters p and the current input
/// values u are set on the object; integrators keep u fixed between control breakpoints.
///
/// Only the effects a scene declares are lowered; a scene without effects gives n_z = 0.
/// The lowering of each effect (gradient form for moving sets, Stewart or Heaviside step
/// form for switching surfaces) is documented with its equations in docs/lowering.md.
///
/// Every complementarity pair has a *continuous side*: the quantity that is continuous in
/// time along solutions (e.g. c(x, t) for a moving set, lambda_i = g_i - min g in Stewart's
/// form). Integrators use it for cross complementarity at element boundaries.

#include <memory>
#include <string>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/model/events.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// How switching surfaces are lowered.
enum class SwitchingForm {
  kStewart,    ///< Stewart's convex-multiplier form (theta, lambda, mu)
  kHeaviside,  ///< Heaviside step form (alpha, lambda_n, lambda_p)
};
std::string ToString(SwitchingForm form);
SwitchingForm ParseSwitchingForm(const std::string& name);

struct LoweringOptions {
  SwitchingForm switching_form = SwitchingForm::kStewart;
};

/// Which derivatives LoweredSystem::Evaluate computes.
enum class Derivatives {
  kNone,    ///< values F, G, A, B only
  kStates,  ///< values and derivatives with respect to y and z
  kAll,     ///< also with respect to the inputs u and the parameters p
};

/// Values (and requested derivatives) of the lowered system at one point (y, z).
struct PointEvaluation {
  Vector F, G, A, B;
  Matrix F_y, F_z, G_y, G_z, A_y, A_z, B_y, B_z;
  /// Sparse F_y, filled instead of F_y (which is then left empty) when the dynamics have a
  /// hand-written sparse Jacobian (MakeSparseStateFunction; such scenes have no effects).
  SparseMatrix F_y_sparse;
  bool has_sparse_F_y = false;
  Matrix F_u, G_u, A_u, B_u;  ///< with Derivatives::kAll
  Matrix F_p, G_p, A_p, B_p;  ///< with Derivatives::kAll
};

/// Which side of a complementarity pair is continuous in time along solutions.
enum class ContinuousSide { kA, kB };

/// Description of one complementarity pair (for events and cross complementarity).
struct PairInfo {
  std::string effect;  ///< name of the effect it comes from
  std::string name;    ///< e.g. "wall.c1" or "circle.theta[outside]"
  ContinuousSide continuous = ContinuousSide::kA;
  int block = 0;  ///< index of the lowered effect (see block_names())
};

/// Which side of a pair is zero: a if a <= b (ties, both zero, count as a = 0).
inline bool PairStatusIsAZero(double a, double b) { return a <= b; }

namespace internal {
class LoweredBlock;
}

/// A scene lowered to a DCS (see file comment).
class LoweredSystem {
 public:
  explicit LoweredSystem(const Scene& scene, const LoweringOptions& options = {});
  ~LoweredSystem();
  LoweredSystem(const LoweredSystem& other);
  LoweredSystem& operator=(const LoweredSystem& other);

  const Scene& scene() const { return scene_; }
  const LoweringOptions& options() const { return options_; }
  int num_states() const { return num_states_; }                ///< n_y
  int num_scene_states() const { return scene_.num_states(); }  ///< n_x (y[0..n_x))
  int clock_index() const { return num_states_ - 1; }
  int num_algebraic() const { return num_algebraic_; }  ///< n_z
  int num_equations() const { return num_equations_; }  ///< n_G
  int num_pairs() const { return num_pairs_; }
  int num_inputs() const { return scene_.num_inputs(); }
  int num_parameters() const { return scene_.num_parameters(); }
  const std::vector<std::string>& state_names() const { return state_names_; }
  const std::vector<std::string>& algebraic_names() const { return algebraic_names_; }
  const std::vector<PairInfo>& pairs() const { return pairs_; }

  /// y0 = (x0, internal initial states, t0).
  Vector InitialState() const;
  /// A guess of the algebraic unknowns at state y, for Newton's first iterate: Stewart's
  /// theta selects the region containing y, Heaviside's alpha follows the signs of c, and
  /// multipliers come from `previous` (or are 0). Where y does not decide (y on a switching
  /// surface), the values in `previous` are kept.
  Vector InitialAlgebraicGuess(const Vector& y, const Vector* previous = nullptr) const;
  /// Sets the input values u used by Evaluate (held constant by integrators within a step).
  void SetInputs(const Vector& u);
  const Vector& inputs() const { return inputs_; }
  /// Sets the parameter values p (defaults: the scene's).
  void SetParameters(const Vector& p);
  const Vector& parameters() const { return parameters_; }

  /// Evaluates F, G, A, B (and derivatives) at (y, z). Not thread-safe (see SmoothFunction).
  void Evaluate(const ConstVectorRef& y, const ConstVectorRef& z, Derivatives derivatives,
                PointEvaluation* out) const;

  /// Number of structurally nonzero entries of F_y (for choosing dense or sparse LU).
  double EstimatedNonzerosFy() const;

  /// Events implied by a change of pair statuses: a_zero[k] is true when pair k has its
  /// first side a_k = 0, false when b_k = 0 (see PairStatusIsAZero).
  std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                  const std::vector<bool>& after) const;

 private:
  void Build();

  Scene scene_;
  LoweringOptions options_;
  int num_states_ = 0;
  int num_algebraic_ = 0;
  int num_equations_ = 0;
  int num_pairs_ = 0;
  std::vector<std::string> state_names_;
  std::vector<std::string> algebraic_names_;
  std::vector<PairInfo> pairs_;
  Vector inputs_;
  Vector parameters_;
  std::vector<std::unique_ptr<internal::LoweredBlock>> blocks_;
  bool sparse_dynamics_ = false;  // dynamics with a hand-written sparse Jacobian
  double nonzeros_fy_ = 0.0;
  mutable Vector x_scratch_, f_scratch_;
  mutable Matrix jac_scratch_;
  mutable SparseMatrix sparse_scratch_;
};

}  // namespace moreau

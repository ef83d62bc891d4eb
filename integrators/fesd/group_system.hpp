#pragma once
// One FESD group as a mixed complementarity system (docs/fesd-formulation.md, "The group
// system"). Private to moreau::integrators.
//
// Unknowns:  w = [element_1 | ... | element_m | v_end | h], element_e = [Z_1; z_1; ...; Z_s; z_s]
//            (v_end and h only with an event equation; otherwise h is fixed).
// Rows, per element e (start state y_e0 = y_start + sum_{e' < e} Z_{e', s}):
//   collocation and algebraic equations at every stage        s (n_y + n_G)
//   status equations a_k = 0 or b_k = 0 at every stage         s n_pairs
// then, with an event equation:
//   velocity-level problem at y_end with the group's statuses n_z
//   one complementarity pair (element-length complementarity):
//     a = (h_max - h) / h_max,   b = min_k w_k iota_k(y_end, v_end) / tau^{p_k},  tau = h / h_ref.

#include <vector>

#include "../common/collocation.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau::internal {

struct GroupSetup {
  Vector y_start;
  std::vector<bool> a_zero;          // status of every pair in the group
  int elements = 1;                  // m
  bool with_event = false;           // h unknown, velocity level and event pair present
  double h_fixed = 0.0;              // element length without event equation
  double h_max = 0.0;                // with event: the length that covers the rest of the step
  double h_reference = 0.0;          // with event: tau = h / h_reference
  Vector indicator_weights;          // w_k > 0 per pair (1 / indicator scale)
  std::vector<int> indicator_power;  // p_k in {0, 2}: 2 for pairs that start at zero
};

class GroupSystem final : public MixedComplementaritySystem {
 public:
  GroupSystem(LoweredSystem* system, int stages);

  // Takes the lowered system's current sizes (after a change of its working set).
  void Resize();
  void Configure(const GroupSetup& setup);
  const GroupSetup& setup() const { return setup_; }

  int element_size() const { return element_size_; }
  int element_offset(int e) const { return e * element_size_; }
  int v_offset() const { return setup_.elements * element_size_; }
  int h_index() const { return v_offset() + nz_; }
  int element_rows() const { return element_rows_; }
  double H(const Vector& w) const { return setup_.with_event ? w[h_index()] : setup_.h_fixed; }
  Vector ElementStart(const ConstVectorRef& w, int e) const;
  void ElementStart(const ConstVectorRef& w, int e, Vector* y) const;  // into *y (reused)
  Vector EndState(const ConstVectorRef& w) const;
  void EndState(const ConstVectorRef& w, Vector* y) const;  // into *y (its storage reused)

  int num_unknowns() const override;
  int num_equations() const override;
  int num_pairs() const override { return setup_.with_event ? 1 : 0; }
  bool Evaluate(const Vector& w, bool with_jacobian, Vector* r, Vector* a, Vector* b) override;
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override;
  void ResidualScale(const Vector& w, Vector* scale) override;
  double EstimatedJacobianNonzeros() const override;

  // Stage data of element e at the last evaluated point (a solve's solution: Newton's last
  // evaluation is at the iterate it returns). After a values-only evaluation (a guess that
  // Newton accepted without derivatives, SemismoothNewtonOptions::defer_initial_jacobian) the
  // stages hold values only: CollocationStages::derivatives() says which.
  const CollocationStages& element(int e) const {
    return (last_with_jacobian_ ? elements_ : value_elements_)[static_cast<std::size_t>(e)];
  }
  // The smallest scaled indicator at the last with-Jacobian evaluation and its pair.
  double event_indicator() const { return event_b_; }
  int event_pair() const { return event_pair_; }

  // Derivatives of all rows (equations, then the event pair with NCP weights da, db) with
  // respect to y_start, the parameters, the inputs and the lengths that depend on the start
  // time (h_fixed, h_max, h_reference), at w after EvaluateForSensitivities.
  struct ParameterBlocks {
    Matrix y_start, p, u;
    Vector h_fixed, h_max, h_reference;
  };
  void EvaluateForSensitivities(const Vector& w);
  // With-Jacobian evaluations also compute the derivatives with respect to p and u, so that
  // one evaluation serves the Jacobian and the parameter blocks (the adjoint sweep).
  void set_parameter_derivatives(bool on) { parameter_derivatives_ = on; }
  void SensitivityBlocks(const Vector& w, double event_da, double event_db,
                         ParameterBlocks* out) const;
  // The same blocks as products, without forming them (group_sensitivity.cpp; directional
  // and adjoint sensitivities of large systems): rhs += B_y dy + B_p dp + B_u du + b_fixed
  // dh_fixed + b_max dh_max + b_reference dh_reference, with B the blocks of
  // SensitivityBlocks (rhs: num_equations() + num_pairs() rows).
  struct LengthChanges {
    double fixed = 0.0, max = 0.0, reference = 0.0;
  };
  void AddBlockProduct(const Vector& w, double event_da, double event_db, const ConstVectorRef& dy,
                       const ConstVectorRef& dp, const ConstVectorRef& du, const LengthChanges& dh,
                       VectorRef rhs) const;
  // The transposed products for weights nu on the rows: dy += B_y^T nu, dp += B_p^T nu,
  // du += B_u^T nu; returns (b_fixed . nu, b_max . nu, b_reference . nu).
  LengthChanges AddTransposedBlockProduct(const Vector& w, double event_da, double event_db,
                                          const ConstVectorRef& nu, VectorRef dy, VectorRef dp,
                                          VectorRef du) const;

 private:
  void EvaluateAll(const Vector& w, Derivatives derivatives,
                   std::vector<CollocationStages>* target);
  LoweredSystem* system_;
  int s_, ny_, nz_, ng_, np_;
  int element_size_ = 0, element_rows_ = 0;
  GroupSetup setup_;
  std::vector<CollocationStages> elements_;        // with-Jacobian evaluations
  std::vector<CollocationStages> value_elements_;  // values-only (line search, deferred)
  bool last_with_jacobian_ = true;                 // which of the two the last Evaluate set
  Vector da_status_, db_status_;                   // status rows: (1, 0) or (0, 1)
  Vector pair_a_, pair_b_;                         // scratch: stage pair sides
  // Scales of the velocity-level rows: 1 / max(1, |row at v = 0|) at y_start (Configure says
  // why).
  Vector velocity_scale_;
  Vector scale_guess_;                    // scratch: the consistent guess the scales are taken at
  std::vector<PairRole> velocity_roles_;  // RolesFor(setup_.a_zero), made by Configure
  Vector start_scratch_;                  // scratch: element start state
  Vector end_scratch_;                    // scratch: the group's end state (with the event)
  VelocityLevelEvaluation velocity_;      // at the last with-Jacobian evaluation
  IndicatorEvaluation indicators_;
  VelocityLevelEvaluation value_velocity_;  // scratch of values-only evaluations
  IndicatorEvaluation value_indicators_;
  double h_jacobian_ = 0.0;
  double event_b_ = 0.0;
  int event_pair_ = -1;
  double tau_ = 1.0;
  bool parameter_derivatives_ = false;
};

}  // namespace moreau::internal

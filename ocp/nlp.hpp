#pragma once
// Private to moreau::ocp: the interface through which SolveOcp hands an NLP of a
// transcription to IPOPT (the shooting NLP, the complementarity-constrained collocation NLP).

#include <string>
#include <utility>
#include <vector>

#include "moreau/core/types.hpp"

namespace moreau::ocp_internal {

// min f(z) s.t. z_lo <= z <= z_hi, c_lo <= c(z) <= c_hi, with exact first derivatives (a
// sparse Jacobian in the order of JacobianStructure()) and, if HessianStructure() is not
// empty, a Hessian (exact or approximate) of objective_factor f + lambda^T c.
class Nlp {
 public:
  virtual ~Nlp() = default;
  virtual int num_variables() const = 0;
  virtual int num_constraints() const = 0;
  virtual const Vector& variable_lower() const = 0;
  virtual const Vector& variable_upper() const = 0;
  virtual const Vector& constraint_lower() const = 0;
  virtual const Vector& constraint_upper() const = 0;
  // Returns false with a message where the functions are not defined (a failed integration).
  virtual bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                        Vector* jacobian_values, std::string* message) = 0;
  virtual const std::vector<std::pair<int, int>>& JacobianStructure() const = 0;
  // Lower triangle (row >= column); empty: IPOPT's limited-memory approximation.
  virtual const std::vector<std::pair<int, int>>& HessianStructure() const = 0;
  // `gradient` and `jacobian_values` are Evaluate's at z.
  virtual bool Hessian(const Vector& z, double objective_factor, const Vector& lambda,
                       const Vector& gradient, const Vector& jacobian_values,
                       Vector* hessian_values) = 0;
};

}  // namespace moreau::ocp_internal

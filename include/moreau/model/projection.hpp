#pragma once
/// @file
/// Projection of a state onto the moving sets of a scene: the state jump of a sweeping process
/// that starts outside its set (Moreau's catching-up step of zero length),
///
///   x = x0 + sum_s E_s E_s^T grad_x c_s(x, t) lambda_s,   0 <= lambda_s ⟂ c_s(x, t) >= 0,
///
/// i.e. the Euclidean projection of x0 onto C(t) = {x : c_s(x, t) >= 0 for all sets s} along
/// each set's projection subspace (for convex sets; in general a stationary point of the
/// distance, found by semismooth Newton from x0). Shooting codes need it: a node state of an
/// NLP iterate may lie outside C(t), and the projected start keeps the shooting map defined
/// and differentiable (derivatives by the implicit function theorem).

#include <string>

#include "moreau/core/types.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// A constraint with c at most this (relative to max(1, |x|)) is on the boundary of its set:
/// the projection's derivative treats it as active (the outward branch, see
/// ProjectOntoMovingSets), and FESD takes the projection's derivative for given initial
/// states this close to the boundary.
inline constexpr double kMovingSetBoundaryTolerance = 1e-10;

/// Result of ProjectOntoMovingSets: the projected state, its multipliers and (with derivatives) the
/// projection's derivatives.
struct MovingSetProjection {
  /// True if the projection problem was solved.
  bool converged = false;
  std::string message;    ///< why not converged
  Vector x;               ///< the projected state
  Vector lambda;          ///< multipliers, one per constraint of all moving sets in order
  double distance = 0.0;  ///< |x - x0|
  /// With derivatives: dx/dx0 (n_x x n_x), dx/dt (n_x), dx/du (n_x x n_u), dx/dp (n_x x n_p).
  Matrix d_x0;
  /// dx/dt (n_x).
  Vector d_t;
  Matrix d_u;  ///< dx/du (n_x x n_u)
  Matrix d_p;  ///< dx/dp (n_x x n_p)
};

/// Projects x0 onto the scene's moving sets at time t, inputs u and parameters p. Scenes
/// without moving sets return x0 unchanged. Derivatives (implicit function theorem on the
/// active-set form) treat every constraint within kMovingSetBoundaryTolerance of zero as
/// active: for x0 on the boundary they are the one-sided derivatives of outward
/// perturbations, the limit of those of infeasible x0 (the map x0 -> x is not differentiable
/// on the boundary; both one-sided derivatives are generalized derivatives). Linearly
/// dependent active gradients leave the derivative undefined: converged = false with the
/// reason.
MovingSetProjection ProjectOntoMovingSets(const Scene& scene, const Vector& x0, double t,
                                          const Vector& u, const Vector& p, bool derivatives);

/// The most violated moving-set constraint at (x, t): min_k c_k(x, t) (+inf without sets).
double MinimumMovingSetConstraint(const Scene& scene, const Vector& x, double t, const Vector& u,
                                  const Vector& p);

}  // namespace moreau

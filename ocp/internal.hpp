#pragma once
// Private to moreau::ocp: the scene the transcription integrates, the Hessian pattern of the
// transcriptions.

#include <algorithm>
#include <cstddef>
#include <initializer_list>
#include <utility>
#include <vector>

#include "moreau/ocp/ocp.hpp"

namespace moreau::ocp_internal {

// The problem's scene extended for the transcription:
//  - a quadrature state "cost" (q' = L, q(t0) = 0) appended to x when there is a running cost;
//    every function with n_x outputs (dynamics, switching modes, relay modes) gets a zero
//    output for it, projection bases a zero row;
//  - a control input "speed" (the speed of time) when the final time is free.
struct AugmentedScene {
  Scene scene;
  int num_states = 0;          // n_x of the problem's scene
  int cost_state = -1;         // index of q in x, or -1
  int speed_input = -1;        // index of the speed in u, or -1
  std::vector<int> decisions;  // decision inputs: the problem's controls, then the speed
};

AugmentedScene Augment(const OcpProblem& problem);

// IPOPT's default "no bound" (nlp_lower_bound_inf / nlp_upper_bound_inf).
inline constexpr double kNoBound = 1e20;

// The free initial states come first among the variables of both transcriptions. Their
// bounds, written into the first entries of *lower and *upper (infinite bounds as kNoBound).
inline void BoundFreeInitialStates(const OcpProblem& problem, Vector* lower, Vector* upper) {
  for (std::size_t i = 0; i < problem.free_initial_states.size(); ++i) {
    const auto& free = problem.free_initial_states[i];
    (*lower)[static_cast<Eigen::Index>(i)] = std::max(free.lower, -kNoBound);
    (*upper)[static_cast<Eigen::Index>(i)] = std::min(free.upper, kNoBound);
  }
}

// Their starting values, written into the first entries of *z: the scene's initial state
// clamped to the bounds.
inline void GuessFreeInitialStates(const OcpProblem& problem, Vector* z) {
  for (std::size_t i = 0; i < problem.free_initial_states.size(); ++i) {
    const auto& free = problem.free_initial_states[i];
    (*z)[static_cast<Eigen::Index>(i)] =
        std::clamp(problem.scene.initial_state[free.state], free.lower, free.upper);
  }
}

// The pattern of a symmetric Hessian assembled from dense blocks, each over a list of
// variables (Block::columns): *structure is the union of the blocks' lower triangles, sorted
// by (row, column) without duplicates, as IPOPT takes it. Each block's Block::position (n * n
// entries, local (i, j) at i * n + j) gets the index in *structure of (columns[i], columns[j])
// where columns[i] >= columns[j], and -1 above the diagonal: every unordered pair of variables
// is stored once. Shared by the shooting and collocation transcriptions.
template <class Block>
void BuildHessianPattern(std::initializer_list<std::vector<Block>*> groups,
                         std::vector<std::pair<int, int>>* structure) {
  structure->clear();
  for (const std::vector<Block>* group : groups) {
    for (const Block& block : *group) {
      for (int a : block.columns) {
        for (int b : block.columns) {
          if (a >= b) structure->emplace_back(a, b);
        }
      }
    }
  }
  std::sort(structure->begin(), structure->end());
  structure->erase(std::unique(structure->begin(), structure->end()), structure->end());
  for (std::vector<Block>* group : groups) {
    for (Block& block : *group) {
      const std::size_t n = block.columns.size();
      block.position.assign(n * n, -1);
      for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t j = 0; j < n; ++j) {
          const int a = block.columns[i];
          const int b = block.columns[j];
          if (a < b) continue;
          const auto it =
              std::lower_bound(structure->begin(), structure->end(), std::make_pair(a, b));
          block.position[i * n + j] = static_cast<int>(it - structure->begin());
        }
      }
    }
  }
}

}  // namespace moreau::ocp_internal

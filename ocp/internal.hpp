#pragma once
// Private to moreau::ocp: the scene the transcription integrates.

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

}  // namespace moreau::ocp_internal

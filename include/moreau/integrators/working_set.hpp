#pragma once
/// @file
/// Diagnostics of the near-active constraint filter (docs/sparse-systems.md, "Near-active
/// constraints") shared by FESD and the time-stepping baseline.

namespace moreau {

/// How often the near-active filter has changed the working set of a lowered system on the
/// calling thread since the thread started (choices at step starts, constraints joining after
/// a failed check, and restorations of a rejected attempt's working set; FESD and
/// time-stepping). A monotone count: its difference across part of a run says whether the
/// element systems changed their unknowns and sparsity pattern in it, which a progress
/// callback cannot see otherwise (tests/integrators/allocation_test.cpp tells the steps that
/// re-plan from steady ones with it).
long WorkingSetChangesOnThisThread();

}  // namespace moreau

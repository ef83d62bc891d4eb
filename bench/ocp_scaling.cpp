// Memory and time of one OCP solve as the number of control intervals N grows (docs/ocp.md,
// "Sparse derivatives"): the structural nonzeros of the constraint Jacobian and of the Hessian
// approximation, the dense constraints x variables matrix they replace, and the process's peak
// resident memory (getrusage: everything, IPOPT's factorizations included). One solve per
// process, so that the peak belongs to that N; scripts/bench-ocp-scaling runs the grid.
//
//   ocp_scaling PROBLEM N [--hessian H] [--homotopy none] [--no-constraint-regularization]
//               [--max-iterations K] [--random-start SEED] [--mesh-continuation N1,N2,...]
//               [--header]
//
// --random-start: controls uniform in their bounds per interval from std::mt19937(SEED), as in
// tests/ocp/ocp_test.cpp (WaveRiderFromRandomStarts). --homotopy none: the exact problem only.
// Prints one CSV row (with --header, the column names first). Opt-in; never part of the tests.
#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include "moreau/ocp/catalog.hpp"

int main(int argc, char** argv) {
  using namespace moreau;
  if (argc < 3) {
    std::fprintf(stderr,
                 "usage: ocp_scaling PROBLEM N [--hessian H] [--max-iterations K] [--header]\n");
    return 2;
  }
  const std::string name = argv[1];
  const int intervals = std::atoi(argv[2]);
  bool header = false;
  long seed = -1;  // < 0: the problem's initial guess
  OcpOptions options;
  try {
    options = MakeOcpOptions(name);
    for (int i = 3; i < argc; ++i) {
      const std::string arg = argv[i];
      if (arg == "--hessian" && i + 1 < argc) {
        options.hessian = ParseOcpHessian(argv[++i]);
      } else if (arg == "--max-iterations" && i + 1 < argc) {
        options.max_iterations = std::atoi(argv[++i]);
      } else if (arg == "--homotopy" && i + 1 < argc && std::string(argv[i + 1]) == "none") {
        options.homotopy.clear();
        ++i;
      } else if (arg == "--no-constraint-regularization") {
        options.regularize_constraints = false;
      } else if (arg == "--random-start" && i + 1 < argc) {
        seed = std::atol(argv[++i]);
      } else if (arg == "--mesh-continuation" && i + 1 < argc) {
        // Comma-separated interval counts (OcpOptions::mesh_continuation).
        options.mesh_continuation.clear();
        const std::string list = argv[++i];
        for (std::size_t p = 0; p <= list.size();) {
          const std::size_t q = std::min(list.find(',', p), list.size());
          options.mesh_continuation.push_back(std::atoi(list.substr(p, q - p).c_str()));
          p = q + 1;
        }
      } else if (arg == "--header") {
        header = true;
      } else {
        std::fprintf(stderr, "ocp_scaling: unknown or incomplete option '%s'\n", arg.c_str());
        return 2;
      }
    }
    OcpProblem problem = MakeOcpProblem(name);
    problem.intervals = intervals;
    problem.initial_controls.resize(0, 0);  // the catalog's guess is for its own N
    if (seed >= 0) {
      std::mt19937 random(static_cast<unsigned>(seed));
      problem.initial_controls.resize(intervals,
                                      static_cast<Eigen::Index>(problem.controls.size()));
      for (Eigen::Index k = 0; k < intervals; ++k) {
        for (Eigen::Index j = 0; j < problem.initial_controls.cols(); ++j) {
          const InputSpec& u = problem.scene.inputs[problem.controls[static_cast<std::size_t>(j)]];
          problem.initial_controls(k, j) =
              std::uniform_real_distribution<double>(u.lower, u.upper)(random);
        }
      }
    }
    const OcpResult result = SolveOcp(problem, options);
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    const ShootingNlp nlp(problem, options);
    const double dense = static_cast<double>(nlp.num_constraints()) * nlp.num_variables();
    if (header) {
      std::printf(
          "problem,N,seed,homotopy_levels,hessian,status,ipopt_iterations,cpu_seconds,objective,"
          "final_time,"
          "variables,constraints,jacobian_nonzeros,hessian_nonzeros,dense_jacobian_entries,"
          "max_rss_kb,resimulated_terminal_error,user_seconds,mesh_continuation\n");
    }
    // CPU time of the process in user mode (the solve and its verification): wall-clock time
    // (cpu_seconds, steady_clock) is unreliable on a shared machine.
    const double user_seconds = static_cast<double>(usage.ru_utime.tv_sec) +
                                1e-6 * static_cast<double>(usage.ru_utime.tv_usec);
    std::string mesh;
    for (int count : options.mesh_continuation) {
      if (count < intervals) mesh += (mesh.empty() ? "" : " ") + std::to_string(count);
    }
    std::printf(
        "%s,%d,%ld,%zu,%s,%s,%d,%.3f,%.12g,%.12g,%d,%d,%ld,%ld,%.0f,%ld,%.3g,%.3f,%s\n",
        name.c_str(), intervals, seed, options.homotopy.size(), ToString(options.hessian).c_str(),
        ToString(result.status).c_str(), result.stats.iterations, result.stats.cpu_seconds,
        result.objective, result.final_time, nlp.num_variables(), nlp.num_constraints(),
        result.stats.jacobian_nonzeros, result.stats.hessian_nonzeros, dense, usage.ru_maxrss,
        result.verified ? result.resimulated_terminal_error : -1.0, user_seconds, mesh.c_str());
  } catch (const std::invalid_argument& error) {
    std::fprintf(stderr, "ocp_scaling: %s\n", error.what());
    return 2;
  }
  return 0;
}

// The rho / step-size study of the alpha-method DAI stepper (docs/alpha-method.md): runs the
// robot (D2) and re-entry (D3) scenes for rho in {0, 0.5, 0.99} and two step sizes each,
// writes one CSV per run, a summary table (summary.csv, summary.md) and gnuplot PNG plots.
//
//   alpha_study [OUTPUT_DIRECTORY]        (default: out/alpha_study)

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "moreau/integrators/alpha_dai.hpp"
#include "moreau/scenes/catalog.hpp"

namespace {

using moreau::AlphaDaiOptions;
using moreau::AlphaDaiResult;
using moreau::AlphaDaiStatus;
using moreau::Scene;
using moreau::Vector;

struct Run {
  std::string scene;
  double rho = 0.0;
  double h = 0.0;
  int max_retries = AlphaDaiOptions().max_retries;
  std::string label;  // file stem
  AlphaDaiResult result;
  double max_phi = 0.0;  // recomputed from the trajectory
};

std::string Format(double value, int digits = 3) {
  std::ostringstream s;
  s << std::setprecision(digits) << value;
  return s.str();
}

// Writes t, states, algebraic inputs, the constraint values phi and the step certificates.
double WriteRunCsv(const Scene& scene, const Run& run, const std::string& path) {
  const auto& dai = std::get<moreau::PathConstraints>(scene.effects[0]);
  const Vector p = scene.ParameterValues();
  const auto& trajectory = run.result.trajectory;
  std::ofstream out(path);
  out << "t";
  for (const std::string& name : trajectory.state_names) out << "," << name;
  for (const std::string& name : trajectory.algebraic_names) out << "," << name;
  for (const std::string& name : dai.constraint_names) out << ",phi_" << name;
  out << ",h,rho,tries,num_active,sigma_min\n" << std::setprecision(12);
  double max_phi = -std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < trajectory.size(); ++k) {
    Vector phi;
    dai.constraints.Evaluate(trajectory.x[k], trajectory.algebraic[k], trajectory.t[k], p, &phi);
    max_phi = std::max(max_phi, phi.maxCoeff());
    out << trajectory.t[k];
    for (Eigen::Index i = 0; i < trajectory.x[k].size(); ++i) out << "," << trajectory.x[k][i];
    for (Eigen::Index i = 0; i < trajectory.algebraic[k].size(); ++i) {
      out << "," << trajectory.algebraic[k][i];
    }
    for (Eigen::Index i = 0; i < phi.size(); ++i) out << "," << phi[i];
    if (k == 0) {
      out << ",0," << run.rho << ",0,0,\n";
      continue;
    }
    const moreau::AlphaDaiStep& step = run.result.steps[k - 1];
    out << "," << step.h << "," << step.rho << "," << step.tries << "," << step.num_active << ","
        << step.basis_sigma_min << "\n";
  }
  return max_phi;
}

bool Gnuplot(const std::string& script_path) {
  const std::string command = "gnuplot '" + script_path + "' 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return false;
  char buffer[256];
  std::string output;
  while (fgets(buffer, sizeof buffer, pipe) != nullptr) output += buffer;
  const int code = pclose(pipe);
  if (code != 0) std::fprintf(stderr, "alpha_study: gnuplot failed:\n%s", output.c_str());
  return code == 0;
}

double Parameter(const Scene& scene, const std::string& name) {
  return scene.parameters[static_cast<std::size_t>(scene.FindParameter(name))].value;
}

// The plot command with one curve per run of `scene` at step h: columns "x:y" of its CSV.
std::string Curves(const std::vector<Run>& runs, const std::string& scene, double h,
                   const std::string& columns, const std::string& style, const std::string& dir) {
  std::string plot;
  for (const Run& run : runs) {
    if (run.scene != scene || run.h != h) continue;
    const bool default_retries = run.max_retries == AlphaDaiOptions().max_retries;
    plot += (plot.empty() ? "plot " : ", ") + std::string("'") + dir + "/" + run.label +
            ".csv' every ::1 using " + columns + " with " + style +
            " title 'rho = " + Format(run.rho) +
            (default_retries ? "" : ", MAXTRY = " + std::to_string(run.max_retries)) + " (" +
            moreau::ToString(run.result.status) + ")'";
  }
  return plot;
}

// D2: the plane paths (obstacles grown by the vehicle radius) and the steering alpha(t).
void PlotD2(const Scene& scene, const std::vector<Run>& runs, double h, const std::string& dir) {
  const std::string script = dir + "/D2_h" + Format(h) + ".gp";
  std::ofstream gp(script);
  gp << "set terminal pngcairo size 1200,900 noenhanced\n"
     << "set output '" << dir << "/D2_h" << Format(h) << ".png'\n"
     << "set datafile separator ','\nset grid\nset key outside right top\n"
     << "set multiplot layout 2,1\n"
     << "set title 'D2 robot paths, h = " << Format(h)
     << " (gray: obstacles grown by the vehicle radius)'\n"
     << "set size ratio -1\nset xlabel 'x (m)'\nset ylabel 'y (m)'\n"
     << "set xrange [-0.5:16]\nset yrange [-2:2]\n";
  const double r_v = Parameter(scene, "r_v");
  for (int i = 1; i <= 3; ++i) {
    const std::string obstacle = "obs" + std::to_string(i);
    gp << "set object " << i << " circle at " << Parameter(scene, obstacle + "_x") << ","
       << Parameter(scene, obstacle + "_y") << " size " << r_v + Parameter(scene, obstacle + "_r")
       << " fc rgb '#cccccc' fs solid noborder behind\n";
  }
  gp << Curves(runs, "D2", h, "2:3", "linespoints pt 7 ps 0.4", dir) << "\n"
     << "unset object 1\nunset object 2\nunset object 3\nset size noratio\nset autoscale\n"
     << "set title 'avoidance steering alpha(t)'\nset xlabel 't (s)'\nset ylabel 'alpha (1/m)'\n"
     << Curves(runs, "D2", h, "1:6", "steps lw 1.5", dir) << "\nunset multiplot\n";
  gp.close();
  Gnuplot(script);
}

// D3: altitude, angle of attack and the heat-flux constraint phi_heat_flux over time.
void PlotD3(const std::vector<Run>& runs, double h, const std::string& dir) {
  const std::string script = dir + "/D3_h" + Format(h) + ".gp";
  std::ofstream gp(script);
  gp << "set terminal pngcairo size 1200,1000 noenhanced\n"
     << "set output '" << dir << "/D3_h" << Format(h) << ".png'\n"
     << "set datafile separator ','\nset grid\nset key outside right top\n"
     << "set multiplot layout 3,1\nset xlabel 't (s)'\n"
     << "set title 'D3 altitude, h = " << Format(h) << "'\nset ylabel 'h (km)'\n"
     << Curves(runs, "D3", h, "1:2", "lines lw 2", dir) << "\n"
     << "set title 'angle of attack (zoom on the activation)'\nset ylabel 'alpha (rad)'\n"
     << "set xrange [78:96]\n"
     << Curves(runs, "D3", h, "1:5", "steps lw 2", dir) << "\n"
     << "set title 'heat-flux constraint phi <= 0 (dashed: the limit)'\n"
     << "set ylabel 'phi_heat_flux (W/cm^2)'\nset yrange [-0.6:0.1]\n"
     << Curves(runs, "D3", h, "1:6", "linespoints pt 7 ps 0.3", dir)
     << ", 0 with lines dt 2 lc rgb 'black' notitle\nunset multiplot\n";
  gp.close();
  Gnuplot(script);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string dir = argc > 1 ? argv[1] : "out/alpha_study";
  std::filesystem::create_directories(dir);
  std::vector<Run> runs;
  auto add = [&runs](const std::string& scene, double rho, double h, int max_retries) {
    Run run;
    run.scene = scene;
    run.rho = rho;
    run.h = h;
    run.max_retries = max_retries;
    runs.push_back(run);
  };
  const int retries = AlphaDaiOptions().max_retries;
  for (double h : {0.1, 0.5}) {
    for (double rho : {0.0, 0.5, 0.99}) add("D2", rho, h, retries);
  }
  add("D2", 0.99, 0.1, 10);  // regularization with a larger retry budget
  for (double h : {0.25, 1.0}) {
    for (double rho : {0.0, 0.5, 0.99}) add("D3", rho, h, retries);
  }
  std::ofstream csv(dir + "/summary.csv");
  std::ofstream md(dir + "/summary.md");
  csv << "scene,rho,h,max_retries,status,t_final,steps,rho_reductions,min_rho,"
         "rank_deficient_tries,min_sigma,active_steps,max_phi,u_variation,sqp_iterations,cpu_"
         "seconds,"
         "message\n";
  md << "| scene | rho | h | MAXTRY | status | t reached | steps | rho reductions | min rho used | "
        "min sigma(B) | steps with active constraints | max phi | total variation of u | SQP "
        "iterations |\n"
     << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (Run& run : runs) {
    const Scene scene = moreau::MakeScene(run.scene);
    AlphaDaiOptions options;
    options.rho = run.rho;
    options.step_size = run.h;
    options.max_retries = run.max_retries;
    run.result = moreau::SimulateAlphaDai(scene, options);
    run.label = run.scene + "_rho" + Format(run.rho) + "_h" + Format(run.h) +
                (run.max_retries != AlphaDaiOptions().max_retries
                     ? "_maxtry" + std::to_string(run.max_retries)
                     : "");
    run.max_phi = WriteRunCsv(scene, run, dir + "/" + run.label + ".csv");
    const moreau::AlphaDaiStats& s = run.result.stats;
    long active_steps = 0;
    for (const moreau::AlphaDaiStep& step : run.result.steps) {
      if (step.num_active > 0) ++active_steps;  // the D2/D3 bounds are path constraints too
    }
    // Total variation sum_n |u_{n+1} - u_n|_inf of the algebraic inputs: step-to-step
    // oscillation of u (undamped as rho -> 1, where 1 - gamma/beta -> -1) shows up here.
    double variation = 0.0;
    const auto& algebraic = run.result.trajectory.algebraic;
    for (std::size_t k = 1; k < algebraic.size(); ++k) {
      variation += (algebraic[k] - algebraic[k - 1]).lpNorm<Eigen::Infinity>();
    }
    const std::string status = moreau::ToString(run.result.status);
    csv << run.scene << "," << run.rho << "," << run.h << "," << run.max_retries << "," << status
        << "," << run.result.final_time << "," << s.num_steps << "," << s.num_rho_reductions << ","
        << s.min_rho << "," << s.num_rank_deficient << "," << s.min_basis_sigma << ","
        << active_steps << "," << run.max_phi << "," << variation << "," << s.num_sqp_iterations
        << "," << s.cpu_seconds << ",\"" << run.result.message.substr(0, 200) << "\"\n";
    md << "| " << run.scene << " | " << run.rho << " | " << run.h << " | " << run.max_retries
       << " | " << status << " | " << Format(run.result.final_time, 4) << " | " << s.num_steps
       << " | " << s.num_rho_reductions << " | " << Format(s.min_rho) << " | "
       << Format(s.min_basis_sigma) << " | " << active_steps << " | " << Format(run.max_phi)
       << " | " << Format(variation) << " | " << s.num_sqp_iterations << " |\n";
    std::printf("%-4s rho = %-4g h = %-4g MAXTRY = %-2d %-22s t = %-8.4g %s\n", run.scene.c_str(),
                run.rho, run.h, run.max_retries, status.c_str(), run.result.final_time,
                s.Summary().c_str());
  }
  const Scene d2 = moreau::MakeScene("D2");
  for (double h : {0.1, 0.5}) PlotD2(d2, runs, h, dir);
  for (double h : {0.25, 1.0}) PlotD3(runs, h, dir);
  std::printf("wrote %s/summary.md, %s/summary.csv, one CSV per run and D2_h*.png, D3_h*.png\n",
              dir.c_str(), dir.c_str());
  return 0;
}

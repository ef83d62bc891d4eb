#pragma once
// Runs the `moreau` executable (MOREAU_CLI_PATH, set by tests/CMakeLists.txt) for the
// command-line tests: exit code and combined stdout/stderr.
#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace moreau::testing {

struct CliOutcome {
  int exit_code = -1;  // -1: not run or killed by a signal
  std::string output;  // stdout and stderr
};

inline CliOutcome RunCli(const std::string& arguments) {
  const std::string command = std::string(MOREAU_CLI_PATH) + " " + arguments + " 2>&1";
  CliOutcome outcome;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return outcome;
  char buffer[512];
  while (fgets(buffer, sizeof buffer, pipe) != nullptr) outcome.output += buffer;
  const int status = pclose(pipe);
  outcome.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return outcome;
}

}  // namespace moreau::testing

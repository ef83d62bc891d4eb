#pragma once
// Command-line flags generated from the integrators' declared options (moreau::Integrators()):
// one flag per option name, shared by the integrators that declare it.

#include <CLI/CLI.hpp>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "moreau/integrators/simulate.hpp"

namespace moreau::tool {

class IntegratorFlags {
 public:
  // Adds --<name> (underscores as dashes) to `command` for every declared option.
  explicit IntegratorFlags(CLI::App* command);
  // The options the user gave, by declared name, as text (bool flags as true/false).
  std::map<std::string, SettingValue> Given() const;

 private:
  struct Flag {
    std::string name;
    bool is_bool = false;
    CLI::Option* option = nullptr;
    std::string text;
    bool value = false;
  };
  std::vector<std::unique_ptr<Flag>> flags_;
};

}  // namespace moreau::tool

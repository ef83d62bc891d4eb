// Model expressions: parser, shared expression graph and the evaluator templated over the
// scalar type (include/moreau/model/expression.hpp).
#include "moreau/model/expression.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numbers>
#include <set>
#include <tuple>

#include "moreau/core/error.hpp"

namespace moreau {
namespace internal {

enum class Op : std::uint8_t {
  kConstant,
  kState,
  kInput,
  kParameter,
  kTime,
  kAdd,
  kSub,
  kMul,
  kDiv,
  kNeg,
  kPowConstant,  // a ^ value (constant exponent)
  kPow,          // a ^ b
  kSin,
  kCos,
  kTan,
  kAsin,
  kAcos,
  kAtan,
  kAtan2,
  kSinh,
  kCosh,
  kTanh,
  kExp,
  kLog,
  kSqrt,
  kHypot,
};

struct Node {
  Op op = Op::kConstant;
  int a = -1;
  int b = -1;
  int index = 0;       // state, input or parameter index
  double value = 0.0;  // constant, or the constant exponent
};

// One evaluation step of a compiled function: operands are slots of the scratch array.
struct Instruction {
  Op op;
  int a;
  int b;
  int index;
  double value;
};

struct Program {
  std::vector<Instruction> code;
  std::vector<int> outputs;                                         // scratch slot of each output
  int needed_states = 0, needed_inputs = 0, needed_parameters = 0;  // largest index + 1
  bool uses_time = false;
};

namespace {

struct FunctionInfo {
  const char* name;
  int arity;
  Op op;
};
constexpr FunctionInfo kFunctions[] = {
    {"sin", 1, Op::kSin},     {"cos", 1, Op::kCos},   {"tan", 1, Op::kTan},
    {"asin", 1, Op::kAsin},   {"acos", 1, Op::kAcos}, {"atan", 1, Op::kAtan},
    {"atan2", 2, Op::kAtan2}, {"sinh", 1, Op::kSinh}, {"cosh", 1, Op::kCosh},
    {"tanh", 1, Op::kTanh},   {"exp", 1, Op::kExp},   {"log", 1, Op::kLog},
    {"sqrt", 1, Op::kSqrt},   {"pow", 2, Op::kPow},   {"hypot", 2, Op::kHypot},
};

// Nonsmooth functions and what models them instead.
struct Refusal {
  const char* name;
  const char* instead;
};
constexpr Refusal kNonsmooth[] = {
    {"abs", "a switching surface on the argument (two modes, one per sign)"},
    {"fabs", "a switching surface on the argument (two modes, one per sign)"},
    {"sign", "a switching surface: the sign is the mode"},
    {"sgn", "a switching surface: the sign is the mode"},
    {"min", "a switching surface on the difference, or a moving set for a bound"},
    {"max", "a switching surface on the difference, or a moving set for a bound"},
    {"floor", "a switching surface or a piecewise-constant input"},
    {"ceil", "a switching surface or a piecewise-constant input"},
    {"round", "a switching surface or a piecewise-constant input"},
    {"heaviside", "a switching surface (Heaviside lowering: --switching heaviside)"},
    {"step", "a switching surface"},
    {"if", "a switching surface (modes) or a hysteresis relay (memory)"},
    {"ifelse", "a switching surface (modes) or a hysteresis relay (memory)"},
    {"mod", "a switching surface"},
    {"fmod", "a switching surface"},
};

constexpr const char* kReserved[] = {"t", "pi", "e"};

}  // namespace

struct ExpressionGraph {
  ExpressionSymbols symbols;
  std::string source;
  std::vector<Node> nodes;
  std::map<std::tuple<int, int, int, int, std::uint64_t>, int> unique;
  std::map<std::string, int> def_nodes;
  std::map<std::string, ExpressionOrigin> def_origins;
  std::vector<std::string> resolving;  // defs being parsed (cycle detection)

  int Add(const Node& node) {
    std::uint64_t bits = 0;
    std::memcpy(&bits, &node.value, sizeof bits);
    const auto key = std::make_tuple(static_cast<int>(node.op), node.a, node.b, node.index, bits);
    const auto found = unique.find(key);
    if (found != unique.end()) return found->second;
    nodes.push_back(node);
    const int id = static_cast<int>(nodes.size()) - 1;
    unique.emplace(key, id);
    return id;
  }
  bool IsConstant(int id) const { return nodes[static_cast<std::size_t>(id)].op == Op::kConstant; }
  double ValueOf(int id) const { return nodes[static_cast<std::size_t>(id)].value; }
  int Constant(double value) { return Add({Op::kConstant, -1, -1, 0, value}); }
  int Unary(Op op, int a);
  int Binary(Op op, int a, int b);
  int Def(const std::string& name, const ExpressionOrigin& use, int column);
};

namespace {

double Apply(Op op, double a, double b) {
  switch (op) {
    case Op::kAdd:
      return a + b;
    case Op::kSub:
      return a - b;
    case Op::kMul:
      return a * b;
    case Op::kDiv:
      return a / b;
    case Op::kNeg:
      return -a;
    case Op::kPow:
      return std::pow(a, b);
    case Op::kSin:
      return std::sin(a);
    case Op::kCos:
      return std::cos(a);
    case Op::kTan:
      return std::tan(a);
    case Op::kAsin:
      return std::asin(a);
    case Op::kAcos:
      return std::acos(a);
    case Op::kAtan:
      return std::atan(a);
    case Op::kAtan2:
      return std::atan2(a, b);
    case Op::kSinh:
      return std::sinh(a);
    case Op::kCosh:
      return std::cosh(a);
    case Op::kTanh:
      return std::tanh(a);
    case Op::kExp:
      return std::exp(a);
    case Op::kLog:
      return std::log(a);
    case Op::kSqrt:
      return std::sqrt(a);
    case Op::kHypot:
      return std::hypot(a, b);
    default:
      return std::nan("");
  }
}

}  // namespace

// Constant operands fold (numbers, pi, e): the graph keeps only what depends on the model's
// variables, whose derivatives the AD needs.
int ExpressionGraph::Unary(Op op, int a) {
  if (IsConstant(a)) return Constant(Apply(op, ValueOf(a), 0.0));
  return Add({op, a, -1, 0, 0.0});
}

int ExpressionGraph::Binary(Op op, int a, int b) {
  if (IsConstant(a) && IsConstant(b)) return Constant(Apply(op, ValueOf(a), ValueOf(b)));
  if (op == Op::kPow && IsConstant(b)) {
    const double exponent = ValueOf(b);
    if (exponent == 1.0) return a;
    if (exponent == 2.0) return Add({Op::kMul, a, a, 0, 0.0});  // x*x, as models write it
    return Add({Op::kPowConstant, a, -1, 0, exponent});
  }
  return Add({op, a, b, 0, 0.0});
}

namespace {

std::string Where(const ExpressionOrigin& origin, int offset) {
  std::string where = origin.source;
  if (origin.line > 0) {
    where += ":" + std::to_string(origin.line) + ":" + std::to_string(origin.column + offset);
  }
  if (!origin.key_path.empty()) where += " (" + origin.key_path + ")";
  return where;
}

// Recursive-descent parser of one expression string (grammar in the header).
class Parser {
 public:
  Parser(ExpressionGraph* graph, const std::string& text, const ExpressionOrigin& origin,
         bool constant_only)
      : graph_(graph), text_(text), origin_(origin), constant_only_(constant_only) {}

  int Parse() {
    // Expressions are bounded: a model line, not a program (keeps recursion shallow).
    if (text_.size() > kMaxLength) Fail(0, "expression longer than ", kMaxLength, " characters");
    Skip();
    if (position_ >= text_.size()) Fail(position_, "empty expression");
    const int node = Expression();
    Skip();
    if (position_ < text_.size()) {
      Fail(position_, "unexpected '", text_[position_], "' after a complete expression",
           Hint(text_[position_]));
    }
    return node;
  }

 private:
  static constexpr std::size_t kMaxLength = 10000;
  static constexpr int kMaxDepth = 200;

  template <class... Args>
  [[noreturn]] void Fail(std::size_t offset, const Args&... args) const {
    ThrowInvalidArgument(Where(origin_, static_cast<int>(offset)), ": ", args..., " in '", text_,
                         "'");
  }

  static std::string Hint(char c) {
    if (c == '<' || c == '>' || c == '=' || c == '!') {
      return " (comparisons are not smooth: model a switch with a switching surface, a bound "
             "with a moving set or path constraint)";
    }
    if (c == '?' || c == ':') return " (conditionals are not smooth: use a switching surface)";
    if (c == '[') return " (refer to states by name, not by index)";
    return "";
  }

  void Skip() {
    while (position_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[position_]))) {
      ++position_;
    }
  }
  bool Accept(char c) {
    Skip();
    if (position_ < text_.size() && text_[position_] == c) {
      ++position_;
      return true;
    }
    return false;
  }

  void Enter() {
    if (++depth_ > kMaxDepth) Fail(position_, "expression nested deeper than ", kMaxDepth);
  }

  // expression := term (('+' | '-') term)*
  int Expression() {
    Enter();
    int left = Term();
    for (;;) {
      if (Accept('+')) {
        left = graph_->Binary(Op::kAdd, left, Term());
      } else if (Accept('-')) {
        left = graph_->Binary(Op::kSub, left, Term());
      } else {
        break;
      }
    }
    --depth_;
    return left;
  }

  // term := unary (('*' | '/') unary)*
  int Term() {
    int left = Unary();
    for (;;) {
      if (Accept('*')) {
        if (position_ < text_.size() && text_[position_] == '*') {
          Fail(position_ - 1, "'**' is not an operator; write powers as a^b");
        }
        left = graph_->Binary(Op::kMul, left, Unary());
      } else if (Accept('/')) {
        left = graph_->Binary(Op::kDiv, left, Unary());
      } else {
        break;
      }
    }
    return left;
  }

  // unary := ('-' | '+') unary | power
  int Unary() {
    Enter();
    int result;
    if (Accept('-')) {
      result = graph_->Unary(Op::kNeg, Unary());
    } else if (Accept('+')) {
      result = Unary();
    } else {
      result = Power();
    }
    --depth_;
    return result;
  }

  // power := primary ('^' unary)?   (right-associative; -x^2 = -(x^2); 2^-1 allowed)
  int Power() {
    const int base = Primary();
    if (Accept('^')) return graph_->Binary(Op::kPow, base, Unary());
    return base;
  }

  int Primary() {
    Skip();
    if (position_ >= text_.size()) Fail(position_, "expression ends where a value is expected");
    const char c = text_[position_];
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '.') return Number();
    if (std::isalpha(static_cast<unsigned char>(c)) || c == '_') return NameOrCall();
    if (c == '(') {
      const std::size_t open = position_++;
      const int inner = Expression();
      if (!Accept(')')) Fail(open, "unclosed '('");
      return inner;
    }
    Fail(position_, "expected a number, a name or '(', got '", c, "'", Hint(c));
  }

  int Number() {
    const std::size_t start = position_;
    while (
        position_ < text_.size() &&
        (std::isdigit(static_cast<unsigned char>(text_[position_])) || text_[position_] == '.')) {
      ++position_;
    }
    if (position_ < text_.size() && (text_[position_] == 'e' || text_[position_] == 'E')) {
      std::size_t exponent = position_ + 1;
      if (exponent < text_.size() && (text_[exponent] == '+' || text_[exponent] == '-')) {
        ++exponent;
      }
      if (exponent < text_.size() && std::isdigit(static_cast<unsigned char>(text_[exponent]))) {
        position_ = exponent;
        while (position_ < text_.size() &&
               std::isdigit(static_cast<unsigned char>(text_[position_]))) {
          ++position_;
        }
      }
    }
    const std::string literal = text_.substr(start, position_ - start);
    char* end = nullptr;
    const double value = std::strtod(literal.c_str(), &end);
    if (end != literal.c_str() + literal.size() || literal == ".") {
      Fail(start, "malformed number '", literal, "'");
    }
    if (!std::isfinite(value)) Fail(start, "number '", literal, "' is not finite");
    return graph_->Constant(value);
  }

  int NameOrCall() {
    const std::size_t start = position_;
    while (
        position_ < text_.size() &&
        (std::isalnum(static_cast<unsigned char>(text_[position_])) || text_[position_] == '_')) {
      ++position_;
    }
    const std::string name = text_.substr(start, position_ - start);
    Skip();
    const bool call = position_ < text_.size() && text_[position_] == '(';
    if (call) {
      // A nonsmooth function (as a call: a parameter may well be named 'floor').
      for (const Refusal& refusal : kNonsmooth) {
        if (name == refusal.name) {
          Fail(start, "'", name,
               "' is not smooth and moreau differentiates model functions "
               "exactly: model it with ",
               refusal.instead);
        }
      }
      for (const FunctionInfo& function : kFunctions) {
        if (name != function.name) continue;
        ++position_;  // '('
        std::vector<int> arguments;
        if (!Accept(')')) {
          do {
            arguments.push_back(Expression());
          } while (Accept(','));
          if (!Accept(')')) Fail(start, "unclosed '(' of ", name, "(...)");
        }
        if (static_cast<int>(arguments.size()) != function.arity) {
          Fail(start, name, " takes ", function.arity, " argument", function.arity == 1 ? "" : "s",
               ", got ", arguments.size());
        }
        return function.arity == 1 ? graph_->Unary(function.op, arguments[0])
                                   : graph_->Binary(function.op, arguments[0], arguments[1]);
      }
      std::vector<std::string> names;
      for (const FunctionInfo& function : kFunctions) names.push_back(function.name);
      const std::string closest = ClosestName(name, names);
      Fail(start, "unknown function '", name, "'",
           closest.empty() ? std::string() : "; did you mean '" + closest + "'?",
           " (functions: sin cos tan asin acos atan atan2 sinh cosh tanh exp log sqrt pow "
           "hypot)");
    }
    return Variable(name, start);
  }

  int Variable(const std::string& name, std::size_t start) {
    if (name == "pi") return graph_->Constant(std::numbers::pi);
    if (name == "e") return graph_->Constant(std::numbers::e);
    const ExpressionSymbols& s = graph_->symbols;
    auto index_of = [&name](const std::vector<std::string>& list) {
      const auto found = std::find(list.begin(), list.end(), name);
      return found == list.end() ? -1 : static_cast<int>(found - list.begin());
    };
    const int parameter = index_of(s.parameters);
    if (parameter >= 0) return graph_->Add({Op::kParameter, -1, -1, parameter, 0.0});
    if (s.defs.count(name) > 0) {
      return graph_->Def(name, origin_, static_cast<int>(start));
    }
    const int state = index_of(s.states), input = index_of(s.inputs);
    if (constant_only_ && (state >= 0 || input >= 0 || name == "t")) {
      Fail(start, "'", name, "' is a ", state >= 0 ? "state" : (input >= 0 ? "input" : "time"),
           "; this value must be a constant (numbers, parameters, pi, e)");
    }
    if (state >= 0) return graph_->Add({Op::kState, -1, -1, state, 0.0});
    if (input >= 0) return graph_->Add({Op::kInput, -1, -1, input, 0.0});
    if (name == "t") return graph_->Add({Op::kTime, -1, -1, 0, 0.0});
    std::vector<std::string> valid = {"t", "pi", "e"};
    for (const auto* list : {&s.states, &s.inputs, &s.parameters}) {
      valid.insert(valid.end(), list->begin(), list->end());
    }
    for (const auto& [def, text] : s.defs) valid.push_back(def);
    const std::string closest = ClosestName(name, valid);
    Fail(start, "unknown name '", name, "'",
         closest.empty() ? std::string() : "; did you mean '" + closest + "'?");
  }

  ExpressionGraph* graph_;
  const std::string& text_;
  ExpressionOrigin origin_;
  bool constant_only_;
  std::size_t position_ = 0;
  int depth_ = 0;
};

}  // namespace

int ExpressionGraph::Def(const std::string& name, const ExpressionOrigin& use, int column) {
  const auto done = def_nodes.find(name);
  if (done != def_nodes.end()) return done->second;
  const auto cycle = std::find(resolving.begin(), resolving.end(), name);
  if (cycle != resolving.end()) {
    std::string chain;
    for (auto it = cycle; it != resolving.end(); ++it) chain += *it + " -> ";
    ThrowInvalidArgument(Where(use, column), ": def '", name, "' refers to itself (", chain, name,
                         ")");
  }
  resolving.push_back(name);
  const auto origin = def_origins.find(name);
  ExpressionOrigin where;
  if (origin != def_origins.end()) {
    where = origin->second;
  } else {
    where.source = source;
    where.key_path = "defs." + name;
  }
  const std::string& text = symbols.defs.at(name);
  const int node = Parser(this, text, where, false).Parse();
  resolving.pop_back();
  def_nodes[name] = node;
  return node;
}

namespace {

// The program of the nodes reachable from `outputs`, in increasing node order (children are
// created before their parents, so that order is topological).
std::shared_ptr<const Program> Compile(const ExpressionGraph& graph,
                                       const std::vector<int>& outputs) {
  std::vector<char> reached(graph.nodes.size(), 0);
  std::vector<int> stack(outputs.begin(), outputs.end());
  while (!stack.empty()) {
    const int id = stack.back();
    stack.pop_back();
    if (reached[static_cast<std::size_t>(id)]) continue;
    reached[static_cast<std::size_t>(id)] = 1;
    const Node& node = graph.nodes[static_cast<std::size_t>(id)];
    if (node.a >= 0) stack.push_back(node.a);
    if (node.b >= 0) stack.push_back(node.b);
  }
  auto program = std::make_shared<Program>();
  std::vector<int> slot(graph.nodes.size(), -1);
  for (std::size_t id = 0; id < graph.nodes.size(); ++id) {
    if (!reached[id]) continue;
    const Node& node = graph.nodes[id];
    slot[id] = static_cast<int>(program->code.size());
    program->code.push_back({node.op, node.a >= 0 ? slot[static_cast<std::size_t>(node.a)] : -1,
                             node.b >= 0 ? slot[static_cast<std::size_t>(node.b)] : -1, node.index,
                             node.value});
    if (node.op == Op::kTime) program->uses_time = true;
    if (node.op == Op::kState)
      program->needed_states = std::max(program->needed_states, node.index + 1);
    if (node.op == Op::kInput)
      program->needed_inputs = std::max(program->needed_inputs, node.index + 1);
    if (node.op == Op::kParameter) {
      program->needed_parameters = std::max(program->needed_parameters, node.index + 1);
    }
  }
  for (int output : outputs) program->outputs.push_back(slot[static_cast<std::size_t>(output)]);
  return program;
}

template <class T>
void Run(const Program& program, const T* x, const T* u, const T& t, const T* p, T* scratch) {
  using std::acos, std::asin, std::atan, std::atan2, std::cos, std::cosh, std::exp, std::log,
      std::pow, std::sin, std::sinh, std::sqrt, std::tan, std::tanh;
  std::size_t k = 0;
  for (const Instruction& in : program.code) {
    T& r = scratch[k++];
    switch (in.op) {
      case Op::kConstant:
        r = T(in.value);
        break;
      case Op::kState:
        r = x[in.index];
        break;
      case Op::kInput:
        r = u[in.index];
        break;
      case Op::kParameter:
        r = p[in.index];
        break;
      case Op::kTime:
        r = t;
        break;
      case Op::kAdd:
        r = scratch[in.a] + scratch[in.b];
        break;
      case Op::kSub:
        r = scratch[in.a] - scratch[in.b];
        break;
      case Op::kMul:
        // x^2 is stored as x*x (one node twice): passed as one object, so that an interval
        // evaluation takes it as the square it is (for other scalars the same product).
        r = in.a == in.b ? scratch[in.a] * scratch[in.a] : scratch[in.a] * scratch[in.b];
        break;
      case Op::kDiv:
        r = scratch[in.a] / scratch[in.b];
        break;
      case Op::kNeg:
        r = -scratch[in.a];
        break;
      case Op::kPowConstant:
        r = pow(scratch[in.a], in.value);
        break;
      case Op::kPow:
        r = pow(scratch[in.a], scratch[in.b]);
        break;
      case Op::kSin:
        r = sin(scratch[in.a]);
        break;
      case Op::kCos:
        r = cos(scratch[in.a]);
        break;
      case Op::kTan:
        r = tan(scratch[in.a]);
        break;
      case Op::kAsin:
        r = asin(scratch[in.a]);
        break;
      case Op::kAcos:
        r = acos(scratch[in.a]);
        break;
      case Op::kAtan:
        r = atan(scratch[in.a]);
        break;
      case Op::kAtan2:
        r = atan2(scratch[in.a], scratch[in.b]);
        break;
      case Op::kSinh:
        r = sinh(scratch[in.a]);
        break;
      case Op::kCosh:
        r = cosh(scratch[in.a]);
        break;
      case Op::kTanh:
        r = tanh(scratch[in.a]);
        break;
      case Op::kExp:
        r = exp(scratch[in.a]);
        break;
      case Op::kLog:
        r = log(scratch[in.a]);
        break;
      case Op::kSqrt:
        r = sqrt(scratch[in.a]);
        break;
      case Op::kHypot: {
        using std::hypot;
        r = hypot(scratch[in.a], scratch[in.b]);
        break;
      }
    }
  }
}

// A model function given by expressions: one program, evaluated for T = double, Dual1, Dual2,
// SparsityTracer (sparsity detection) and Interval (enclosures over boxes).
class ExpressionFunction final : public TypedFunctionFor<ExpressionFunction> {
  using Base = TypedFunctionFor<ExpressionFunction>;
  friend Base;

 public:
  ExpressionFunction(std::string name, std::shared_ptr<const Program> program)
      : Base(std::move(name), static_cast<int>(program->outputs.size())),
        program_(std::move(program)) {}
  std::unique_ptr<SmoothFunction::Concept> Clone() const override {
    return ShareAnalysis(std::make_unique<ExpressionFunction>(name_, program_));
  }

 private:
  template <class T>
  std::vector<T>& Scratch() {
    if constexpr (std::is_same_v<T, double>) {
      return scratch0_;
    } else if constexpr (std::is_same_v<T, Dual1>) {
      return scratch1_;
    } else if constexpr (std::is_same_v<T, Dual2>) {
      return scratch2_;
    } else if constexpr (std::is_same_v<T, Interval>) {
      return scratch_interval_;
    } else {
      static_assert(std::is_same_v<T, SparsityTracer>);
      return scratch_trace_;
    }
  }

  template <class T>
  void Invoke(const T* x, int nx, const T* u, int nu, const T& t, const T* p, int np, T* out) {
    const Program& program = *program_;
    if (nx < program.needed_states) ThrowArgumentIndex(name_, "x", program.needed_states - 1, nx);
    if (nu < program.needed_inputs) ThrowArgumentIndex(name_, "u", program.needed_inputs - 1, nu);
    if (np < program.needed_parameters) {
      ThrowArgumentIndex(name_, "p", program.needed_parameters - 1, np);
    }
    std::vector<T>& scratch = Scratch<T>();
    scratch.resize(program.code.size());
    Run(program, x, u, t, p, scratch.data());
    for (std::size_t k = 0; k < program.outputs.size(); ++k)
      out[k] = scratch[static_cast<std::size_t>(program.outputs[k])];
  }

  std::shared_ptr<const Program> program_;
  std::vector<double> scratch0_;
  std::vector<Dual1> scratch1_;
  std::vector<Dual2> scratch2_;
  std::vector<SparsityTracer> scratch_trace_;
  std::vector<Interval> scratch_interval_;
};

}  // namespace
}  // namespace internal

std::string ClosestName(const std::string& name, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_distance = std::string::npos;
  for (const std::string& candidate : candidates) {
    // Levenshtein distance with one row.
    std::vector<std::size_t> row(candidate.size() + 1);
    for (std::size_t j = 0; j <= candidate.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= name.size(); ++i) {
      std::size_t diagonal = row[0];
      row[0] = i;
      for (std::size_t j = 1; j <= candidate.size(); ++j) {
        const std::size_t up = row[j];
        row[j] = std::min(
            {row[j] + 1, row[j - 1] + 1, diagonal + (name[i - 1] == candidate[j - 1] ? 0 : 1)});
        diagonal = up;
      }
    }
    const std::size_t distance = row[candidate.size()];
    const std::size_t limit = std::max<std::size_t>(1, std::max(name.size(), candidate.size()) / 3);
    // Close, and not a complete replacement (a one-letter name has no close alternative).
    if (distance <= limit && distance < name.size() && distance < best_distance) {
      best_distance = distance;
      best = candidate;
    }
  }
  return best;
}

ExpressionModel::ExpressionModel(ExpressionSymbols symbols, std::string source)
    : graph_(std::make_unique<internal::ExpressionGraph>()) {
  // Every name means one thing.
  std::map<std::string, std::string> kinds;
  auto declare = [&kinds](const std::string& name, const std::string& kind) {
    const auto [it, inserted] = kinds.emplace(name, kind);
    RequireArgument(inserted, "duplicate name '", name, "' (", it->second, " and ", kind, ")");
  };
  for (const char* reserved : internal::kReserved) kinds.emplace(reserved, "a reserved name");
  for (const auto& f : internal::kFunctions) kinds.emplace(f.name, "a function");
  for (const std::string& n : symbols.states) declare(n, "a state");
  for (const std::string& n : symbols.inputs) declare(n, "an input");
  for (const std::string& n : symbols.parameters) declare(n, "a parameter");
  for (const auto& [n, text] : symbols.defs) declare(n, "a def");
  graph_->symbols = std::move(symbols);
  graph_->source = std::move(source);
}

ExpressionModel::~ExpressionModel() = default;
ExpressionModel::ExpressionModel(ExpressionModel&&) noexcept = default;
ExpressionModel& ExpressionModel::operator=(ExpressionModel&&) noexcept = default;

void ExpressionModel::SetDefOrigin(const std::string& def, const ExpressionOrigin& origin) {
  graph_->def_origins[def] = origin;
}

SmoothFunction ExpressionModel::Function(const std::string& name,
                                         const std::vector<std::string>& expressions,
                                         const std::vector<ExpressionOrigin>& origins) {
  std::vector<int> outputs;
  for (std::size_t k = 0; k < expressions.size(); ++k) {
    ExpressionOrigin origin;
    if (k < origins.size()) {
      origin = origins[k];
    } else {
      origin.source = graph_->source;
    }
    outputs.push_back(internal::Parser(graph_.get(), expressions[k], origin, false).Parse());
  }
  return SmoothFunction(
      std::make_unique<internal::ExpressionFunction>(name, internal::Compile(*graph_, outputs)));
}

double ExpressionModel::Constant(const std::string& expression, const ExpressionOrigin& origin,
                                 const std::vector<double>& parameter_values) {
  const int node = internal::Parser(graph_.get(), expression, origin, true).Parse();
  const auto program = internal::Compile(*graph_, {node});
  RequireArgument(program->needed_states == 0 && program->needed_inputs == 0 && !program->uses_time,
                  internal::Where(origin, 0), ": '", expression,
                  "' must be a constant (numbers, parameters, pi, e)");
  RequireArgument(static_cast<int>(parameter_values.size()) >= program->needed_parameters,
                  internal::Where(origin, 0), ": parameters are not known here");
  std::vector<double> scratch(program->code.size());
  const double t = 0.0;
  internal::Run(*program, static_cast<const double*>(nullptr), static_cast<const double*>(nullptr),
                t, parameter_values.data(), scratch.data());
  return scratch[static_cast<std::size_t>(program->outputs[0])];
}

int ExpressionModel::num_nodes() const { return static_cast<int>(graph_->nodes.size()); }

}  // namespace moreau

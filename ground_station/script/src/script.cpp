// Task script parser and checker (script.hpp). A small table per command
// says which positional values and which keys it takes, and their types; one
// tokenizer keeps the column of every token so each message can point at it.
#include "foresight/script/script.hpp"

#include "foresight/common/text_file.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include "foresight/common/format.hpp"

namespace foresight::script {
namespace {

enum class Type { Number, Positive, Fraction, Numbers, Name, Names, Choice, Flag, Path, Goals };

struct ValueSpec {
  ValueSpec(std::string key_, Type type_, std::vector<std::string> choices_ = {}, bool required_ = false,
            int count_ = 0)
      : key(std::move(key_)), type(type_), choices(std::move(choices_)), required(required_), count(count_) {}
  std::string key;  ///< for positional values: what it is, for messages
  Type type = Type::Name;
  std::vector<std::string> choices;  ///< Type::Choice
  bool required = false;
  int count = 0;  ///< Type::Numbers: exact element count (0 = any)
};

struct OpSpec {
  Op op;
  const char* word;
  bool remote;
  std::vector<ValueSpec> positional;  ///< in order; required ones first
  std::vector<ValueSpec> named;
  bool open_keys = false;  ///< any other key=number (INVOKE_ALGORITHM parameters)
};

const std::vector<std::string> kAlgorithms = {"guarded_move", "insert",   "latch", "unlatch",         "loosen",
                                              "tighten",      "pull_out", "tare",  "identify_payload"};

const std::vector<OpSpec>& specs() {
  static const std::vector<OpSpec> table = {
      {Op::Graphics, "GRAPHICS", false, {{"mode", Type::Choice, {"wire", "solid", "hidden", "ghost", "off"}, true}}, {}},
      {Op::Video, "VIDEO", false, {{"camera", Type::Name, {}, true}}, {}},
      {Op::Object, "OBJECT", false, {{"object", Type::Name, {}, true}}, {{"pose", Type::Path}}},
      {Op::Frame, "FRAME", false, {{"frame", Type::Choice, {"world", "tool", "camera", "object"}, true}}, {}},
      {Op::Tag, "TAG", false, {{"tag", Type::Name, {}, true}}, {}},
      {Op::Grab, "GRAB", false, {}, {}},
      {Op::Release, "RELEASE", false, {}, {}},
      {Op::Wait, "WAIT", false, {}, {}},
      {Op::Preview,
       "PREVIEW",
       false,
       {},
       {{"to", Type::Goals, {}, true},
        {"camera", Type::Name},
        {"speed_m_s", Type::Positive},
        {"limit", Type::Fraction},
        {"dwell_s", Type::Number}}},
      {Op::Calibrate, "CALIBRATE", false, {}, {{"cameras", Type::Names}, {"points", Type::Path}}},
      {Op::Localize, "LOCALIZE", false, {}, {{"views", Type::Names}, {"points", Type::Path}}},
      {Op::Check,
       "CHECK",
       false,
       {{"step", Type::Choice, {"insert"}, true}},
       {{"tag", Type::Name},
        {"hole", Type::Name},
        {"min_p", Type::Fraction},
        {"depth_m", Type::Positive},
        {"spiral_max_radius_m", Type::Positive}}},
      {Op::Trajectory,
       "TRAJECTORY",
       true,
       {},
       {{"to", Type::Goals, {}, true},
        {"compliant", Type::Flag},
        {"speed_m_s", Type::Positive},
        {"limit", Type::Fraction},
        {"dwell_s", Type::Number}}},
      {Op::InvokeAlgorithm,
       "INVOKE_ALGORITHM",
       true,
       {{"algorithm", Type::Choice, kAlgorithms, true}},
       {{"timeout_s", Type::Positive}},
       true},
      {Op::Request,
       "REQUEST",
       true,
       {{"what", Type::Choice, {"joints", "wrench", "tool", "status", "trajectories"}, true}},
       {}},
      {Op::Camera,
       "CAMERA",
       true,
       {{"camera", Type::Name, {}, true}},
       {{"action", Type::Choice, {"select", "point", "grab"}},
        {"pan_deg", Type::Number},
        {"tilt_deg", Type::Number},
        {"focal_px", Type::Positive}}},
      {Op::GotoJoint,
       "GOTO_JOINT",
       true,
       {{"target", Type::Choice, {"start"}}},
       {{"q", Type::Numbers}, {"q_deg", Type::Numbers}, {"speed", Type::Fraction}}},
      {Op::GotoCart,
       "GOTO_CART",
       true,
       {},
       {{"tag", Type::Name},
        {"xyz_m", Type::Numbers, {}, false, 3},
        {"rpy_deg", Type::Numbers, {}, false, 3},
        {"speed", Type::Fraction}}},
  };
  return table;
}

const OpSpec& spec_of(Op op) {
  for (const auto& s : specs())
    if (s.op == op) return s;
  return specs().front();  // unreachable: every Op has a row
}

std::string join(const std::vector<std::string>& items, const char* sep = ", ") {
  std::string out;
  for (const auto& i : items) out += (out.empty() ? "" : sep) + i;
  return out;
}

bool is_name(const std::string& s) {
  if (s.empty() || !(std::isalpha(static_cast<unsigned char>(s[0])) || s[0] == '_')) return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

bool parse_double(const std::string& s, double& out) {
  if (s.empty()) return false;
  char* end = nullptr;
  out = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size() && std::isfinite(out);
}

struct Token {
  std::string text;
  int column;
};

/// Splits a comma list with the column of each element.
std::vector<Value> split_list(const Value& v) {
  std::vector<Value> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = v.text.find(',', start);
    const std::size_t end = comma == std::string::npos ? v.text.size() : comma;
    out.push_back({v.text.substr(start, end - start), v.column + static_cast<int>(start)});
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

class Parser {
 public:
  explicit Parser(std::string file) : file_(std::move(file)) {}

  [[noreturn]] void fail(int line, int column, const std::string& message) const {
    throw ScriptError(file_, line, column, message);
  }

  void check_value(int line, const std::string& what, const ValueSpec& spec, const Value& v) const {
    const std::string quoted = "'" + v.text + "'";
    switch (spec.type) {
      case Type::Number:
      case Type::Positive:
      case Type::Fraction: {
        double x = 0;
        if (!parse_double(v.text, x)) fail(line, v.column, what + ": " + quoted + " is not a finite number");
        if (spec.type == Type::Positive && !(x > 0)) fail(line, v.column, what + " must be > 0, not " + v.text);
        if (spec.type == Type::Fraction && !(x > 0 && x <= 1))
          fail(line, v.column, what + " must be in (0, 1], not " + v.text);
        break;
      }
      case Type::Numbers: {
        const auto elements = split_list(v);
        for (std::size_t i = 0; i < elements.size(); ++i) {
          double x = 0;
          if (!parse_double(elements[i].text, x))
            fail(line, elements[i].column,
                 what + ": element " + std::to_string(i + 1) + " ('" + elements[i].text + "') is not a finite number");
        }
        if (spec.count > 0 && static_cast<int>(elements.size()) != spec.count)
          fail(line, v.column,
               what + " needs " + std::to_string(spec.count) + " numbers, not " + std::to_string(elements.size()));
        break;
      }
      case Type::Name:
        if (!is_name(v.text)) fail(line, v.column, what + ": " + quoted + " is not a name");
        break;
      case Type::Names:
        for (const auto& e : split_list(v))
          if (!is_name(e.text)) fail(line, e.column, what + ": '" + e.text + "' is not a name");
        break;
      case Type::Choice:
        if (std::find(spec.choices.begin(), spec.choices.end(), v.text) == spec.choices.end())
          fail(line, v.column, what + ": " + quoted + " is not one of " + join(spec.choices));
        break;
      case Type::Flag:
        if (v.text != "yes" && v.text != "no" && v.text != "true" && v.text != "false" && v.text != "1" &&
            v.text != "0")
          fail(line, v.column, what + ": " + quoted + " is not yes or no");
        break;
      case Type::Path:
        if (v.text.empty()) fail(line, v.column, what + ": empty path");
        break;
      case Type::Goals:
        for (const auto& e : split_list(v)) {
          const std::size_t colon = e.text.find(':');
          const std::string name = e.text.substr(0, colon);
          if (!is_name(name)) fail(line, e.column, what + ": '" + e.text + "' is not a goal (TAG[:linear|:joint] or start)");
          if (colon != std::string::npos) {
            const std::string kind = e.text.substr(colon + 1);
            if (kind != "linear" && kind != "joint")
              fail(line, e.column + static_cast<int>(colon) + 1,
                   what + ": '" + e.text + "': the move kind after ':' must be linear or joint");
            if (name == "start" && kind == "linear")
              fail(line, e.column, what + ": 'start' is a joint-space goal; it cannot be linear");
          }
        }
        break;
    }
  }

  Command parse_line(const std::string& raw, int line) {
    // Strip the comment; keep it as the note.
    std::string body = raw;
    std::string note;
    if (const std::size_t hash = raw.find('#'); hash != std::string::npos) {
      body = raw.substr(0, hash);
      note = raw.substr(hash + 1);
      const auto b = note.find_first_not_of(" \t");
      const auto e = note.find_last_not_of(" \t\r");
      note = b == std::string::npos ? "" : note.substr(b, e - b + 1);
    }
    std::vector<Token> tokens;
    for (std::size_t i = 0; i < body.size();) {
      if (body[i] == ' ' || body[i] == '\t' || body[i] == '\r') {
        ++i;
        continue;
      }
      if (static_cast<unsigned char>(body[i]) < 0x20)
        fail(line, static_cast<int>(i) + 1, "unexpected control character");
      const std::size_t start = i;
      while (i < body.size() && body[i] != ' ' && body[i] != '\t' && body[i] != '\r') ++i;
      tokens.push_back({body.substr(start, i - start), static_cast<int>(start) + 1});
    }
    Command c;
    c.line = line;
    c.note = note;
    if (tokens.empty()) return c;  // caller skips it (column 0)
    c.column = tokens[0].column;
    {
      const auto b = body.find_first_not_of(" \t");
      const auto e = body.find_last_not_of(" \t\r");
      c.text = body.substr(b, e - b + 1);
    }
    const std::string word = upper(tokens[0].text);
    const OpSpec* spec = nullptr;
    for (const auto& s : specs())
      if (word == s.word) spec = &s;
    if (spec == nullptr) {
      std::vector<std::string> words;
      for (const auto& s : specs()) words.emplace_back(s.word);
      fail(line, c.column, "unknown command '" + tokens[0].text + "' (commands: " + join(words) + ")");
    }
    c.op = spec->op;
    const std::string w = spec->word;
    for (std::size_t k = 1; k < tokens.size(); ++k) {
      const Token& t = tokens[k];
      const std::size_t eq = t.text.find('=');
      if (eq == std::string::npos) {
        if (!c.named.empty())
          fail(line, t.column, w + ": '" + t.text + "' must come before the key=value options");
        if (c.positional.size() >= spec->positional.size())
          fail(line, t.column,
               spec->positional.empty() ? w + " takes no positional value, got '" + t.text + "'"
                                        : w + ": unexpected extra value '" + t.text + "'");
        const ValueSpec& vs = spec->positional[c.positional.size()];
        Value v{t.text, t.column};
        check_value(line, w + " " + vs.key, vs, v);
        c.positional.push_back(v);
        continue;
      }
      const std::string key = t.text.substr(0, eq);
      Value v{t.text.substr(eq + 1), t.column + static_cast<int>(eq) + 1};
      if (key.empty()) fail(line, t.column, w + ": '" + t.text + "' has no key before '='");
      if (v.text.empty()) fail(line, t.column, w + ": " + key + "= has no value");
      if (c.named.count(key) != 0) fail(line, t.column, w + ": " + key + " is given twice");
      const ValueSpec* ks = nullptr;
      for (const auto& n : spec->named)
        if (n.key == key) ks = &n;
      if (ks == nullptr) {
        if (!spec->open_keys) {
          std::vector<std::string> keys;
          for (const auto& n : spec->named) keys.push_back(n.key);
          fail(line, t.column,
               w + ": unknown key '" + key + "'" + (keys.empty() ? " (it takes none)" : " (keys: " + join(keys) + ")"));
        }
        if (!is_name(key)) fail(line, t.column, w + ": '" + key + "' is not a parameter name");
        static const ValueSpec number{"", Type::Number};
        check_value(line, w + " " + key, number, v);
      } else {
        check_value(line, w + " " + key, *ks, v);
      }
      c.named[key] = v;
    }
    const int end_column = static_cast<int>(body.find_last_not_of(" \t\r")) + 2;
    for (std::size_t k = c.positional.size(); k < spec->positional.size(); ++k)
      if (spec->positional[k].required) {
        const auto& ps = spec->positional[k];
        fail(line, end_column,
             w + ": missing " + ps.key + (ps.type == Type::Choice ? " (" + join(ps.choices, " | ") + ")" : ""));
      }
    for (const auto& n : spec->named)
      if (n.required && c.named.count(n.key) == 0) fail(line, end_column, w + ": missing " + n.key + "=");
    // Combinations.
    if (c.op == Op::GotoJoint) {
      const int given = static_cast<int>(!c.positional.empty()) + static_cast<int>(c.has("q")) +
                        static_cast<int>(c.has("q_deg"));
      if (given == 0) fail(line, end_column, "GOTO_JOINT: missing the target: q=, q_deg= or start");
      if (given > 1) {
        const Value& second = c.has("q_deg") ? c.named.at("q_deg") : c.named.at("q");
        fail(line, second.column, "GOTO_JOINT: give one target: q=, q_deg= or start");
      }
    }
    if (c.op == Op::GotoCart) {
      if (!c.has("tag") && !c.has("xyz_m")) fail(line, end_column, "GOTO_CART: missing the target: tag= or xyz_m=");
      if (c.has("tag") && c.has("xyz_m")) fail(line, c.named.at("xyz_m").column, "GOTO_CART: give tag= or xyz_m=, not both");
      if (c.has("tag") && c.has("rpy_deg"))
        fail(line, c.named.at("rpy_deg").column, "GOTO_CART: rpy_deg= goes with xyz_m=, not tag=");
    }
    return c;
  }

 private:
  std::string file_;
};

}  // namespace

const char* to_string(Op op) noexcept { return spec_of(op).word; }
bool is_remote(Op op) noexcept { return spec_of(op).remote; }
const std::vector<std::string>& algorithm_names() { return kAlgorithms; }

std::string Command::text_or(const std::string& key, const std::string& fallback) const {
  const auto it = named.find(key);
  return it == named.end() ? fallback : it->second.text;
}

double Command::number_or(const std::string& key, double fallback) const {
  const auto it = named.find(key);
  return it == named.end() ? fallback : std::strtod(it->second.text.c_str(), nullptr);
}

std::vector<double> Command::numbers(const std::string& key) const {
  std::vector<double> out;
  const auto it = named.find(key);
  if (it == named.end()) return out;
  for (const auto& e : split_list(it->second)) out.push_back(std::strtod(e.text.c_str(), nullptr));
  return out;
}

std::vector<std::string> Command::names(const std::string& key) const {
  std::vector<std::string> out;
  const auto it = named.find(key);
  if (it == named.end()) return out;
  for (const auto& e : split_list(it->second)) out.push_back(e.text);
  return out;
}

bool Command::flag_or(const std::string& key, bool fallback) const {
  const auto it = named.find(key);
  if (it == named.end()) return fallback;
  return it->second.text == "yes" || it->second.text == "true" || it->second.text == "1";
}

std::vector<std::pair<std::string, double>> Command::parameters() const {
  std::vector<std::pair<std::string, double>> out;
  for (const auto& [k, v] : named)
    if (k != "timeout_s") out.emplace_back(k, std::strtod(v.text.c_str(), nullptr));
  return out;
}

Script parse_script(const std::string& text, const std::string& file) {
  Parser parser(file);
  Script s;
  s.file = file;
  std::istringstream in(text);
  std::string raw;
  int line = 0;
  while (std::getline(in, raw)) {
    ++line;
    Command c = parser.parse_line(raw, line);
    if (c.column > 0) s.commands.push_back(std::move(c));
  }
  return s;
}

Script load_script(const std::string& path) {
  // Bounded (a script is a page of text, /dev/zero is refused), never a FIFO or a directory.
  return parse_script(read_text_file(path, "cannot open script", limits::kMaxScriptBytes), path);
}

std::vector<GoalSpec> goals_of(const Command& command) {
  std::vector<GoalSpec> out;
  const auto it = command.named.find("to");
  if (it == command.named.end()) return out;
  for (const auto& e : split_list(it->second)) {
    const std::size_t colon = e.text.find(':');
    out.push_back({e.text.substr(0, colon), colon != std::string::npos && e.text.substr(colon + 1) == "linear",
                   e.column});
  }
  return out;
}

void check_script(const Script& script, const ScriptContext& ctx) {
  const auto fail = [&](const Command& c, int column, const std::string& message) {
    throw ScriptError(script.file, c.line, column, message);
  };
  const auto in = [](const std::set<std::string>& set, const std::string& name) {
    return set.empty() || set.count(name) != 0;
  };
  const auto listing = [](const std::set<std::string>& set) {
    return join(std::vector<std::string>(set.begin(), set.end()));
  };
  const auto tag = [&](const Command& c, const std::string& name, int column) {
    if (!in(ctx.tags, name)) fail(c, column, "unknown tag '" + name + "' (tags: " + listing(ctx.tags) + ")");
  };
  const auto camera = [&](const Command& c, const std::string& name, int column) {
    if (!in(ctx.cameras, name))
      fail(c, column, "unknown camera '" + name + "' (cameras: " + listing(ctx.cameras) + ")");
  };
  const auto camera_list = [&](const Command& c, const std::string& key) {
    const auto it = c.named.find(key);
    if (it == c.named.end()) return;
    for (const auto& e : split_list(it->second)) camera(c, e.text, e.column);
  };
  for (const Command& c : script.commands) {
    switch (c.op) {
      case Op::Video:
      case Op::Camera:
        camera(c, c.positional[0].text, c.positional[0].column);
        break;
      case Op::Preview:
        if (c.has("camera")) camera(c, c.named.at("camera").text, c.named.at("camera").column);
        [[fallthrough]];
      case Op::Trajectory:
        for (const auto& g : goals_of(c))
          if (g.name != "start") tag(c, g.name, g.column);
        break;
      case Op::Tag:
        tag(c, c.positional[0].text, c.positional[0].column);
        break;
      case Op::GotoCart:
        if (c.has("tag")) tag(c, c.named.at("tag").text, c.named.at("tag").column);
        break;
      case Op::Check:
        for (const char* key : {"tag", "hole"})
          if (c.has(key)) tag(c, c.named.at(key).text, c.named.at(key).column);
        break;
      case Op::Object:
        if (!in(ctx.objects, c.positional[0].text))
          fail(c, c.positional[0].column,
               "unknown object '" + c.positional[0].text + "' (objects: " + listing(ctx.objects) + ")");
        break;
      case Op::Calibrate:
        camera_list(c, "cameras");
        break;
      case Op::Localize:
        camera_list(c, "views");
        break;
      case Op::GotoJoint: {
        const bool deg = c.has("q_deg");
        const std::string key = deg ? "q_deg" : "q";
        if (!c.has(key)) break;
        const Value& v = c.named.at(key);
        const auto q = c.numbers(key);
        if (ctx.joints > 0 && static_cast<int>(q.size()) != ctx.joints)
          fail(c, v.column,
               key + " has " + std::to_string(q.size()) + " values but the arm has " + std::to_string(ctx.joints) +
                   " joints");
        if (ctx.lower_rad.size() == q.size() && ctx.upper_rad.size() == q.size()) {
          const auto elements = split_list(v);
          const double scale = deg ? M_PI / 180.0 : 1.0;
          for (std::size_t i = 0; i < q.size(); ++i) {
            const double r = q[i] * scale;
            if (r < ctx.lower_rad[i] || r > ctx.upper_rad[i]) {
              char buf[160];
              const double s = deg ? 180.0 / M_PI : 1.0;
              std::snprintf(buf, sizeof buf, "%s: joint%zu = %s %s is outside its limits [%.2f, %.2f] %s",
                            key.c_str(), i + 1, elements[i].text.c_str(), deg ? "deg" : "rad",
                            ctx.lower_rad[i] * s, ctx.upper_rad[i] * s, deg ? "deg" : "rad");
              fail(c, elements[i].column, buf);
            }
          }
        }
        break;
      }
      default:
        break;
    }
  }
}

}  // namespace foresight::script

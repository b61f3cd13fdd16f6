#pragma once
// Task scripts: the paper's auto sequence as a small text file, one command a
// line (docs/operator.md, "Task scripts"). Not real-time code: parsing and
// checking happen on the ground before anything is sent.
//
//   # the ORU changeout            <- a comment; `#` starts one anywhere
//   VIDEO oblique                  <- COMMAND positional... key=value...
//   TRAJECTORY to=approach_20cm    # approach to 20 cm   <- trailing note
//   INVOKE_ALGORITHM latch timeout_s=20
//
// Command words are case-insensitive; values are case-sensitive. Every value is
// checked by type when parsed (a number, a comma list of numbers, a name, one
// of a fixed set); names that depend on the configuration (tags, cameras, the
// arm's joint count and limits) are checked by check_script(). Each error
// names the file, line and column: "FILE:LINE:COL: message".

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "foresight/common/error.hpp"

namespace foresight::script {

/// A syntax or semantic error in a script. what() reads
/// "<file>:<line>:<column>: <message>" (an InputError: the CLI exits 2).
class ScriptError : public InputError {
 public:
  ScriptError(const std::string& file, int line, int column, const std::string& message)
      : InputError(file, line, message),
        column_(column),
        message_(message),
        what_(file + ":" + std::to_string(line) + ":" + std::to_string(column) + ": " + message) {}
  const char* what() const noexcept override { return what_.c_str(); }
  /// 1-based column of the offending token or element.
  int column() const noexcept { return column_; }
  /// The message without the location.
  const std::string& message() const noexcept { return message_; }

 private:
  int column_;
  std::string message_;
  std::string what_;
};

enum class Op {
  // local: the ground's display and models
  Graphics,   ///< GRAPHICS wire|solid|hidden|ghost|off
  Video,      ///< VIDEO CAMERA: the video source shown
  Object,     ///< OBJECT NAME [pose=localize.json]
  Frame,      ///< FRAME world|tool|camera|object: the reference frame (display, teleoperation)
  Tag,        ///< TAG NAME: show and select a tag point of the object
  Grab,       ///< GRAB: the object's graphics move with the tool from here
  Release,    ///< RELEASE: the object's graphics stay where they are
  Preview,    ///< PREVIEW to=GOALS [...]: plan and render, nothing sent
  Calibrate,  ///< CALIBRATE [cameras=a,b] [points=arm.csv]
  Localize,   ///< LOCALIZE [views=a,b] [points=oru.csv]
  Wait,       ///< WAIT: the end of a chain (`run --chain`): every command sent ahead has ended before the next
  Check,      ///< CHECK insert [tag=] [hole=] [min_p=] [depth_m=] [spiral_max_radius_m=]: the go/no-go before contact
  // remote: sent to the robot; each waits for its final acknowledgement, or with
  // `run --chain` TRAJECTORY, INVOKE_ALGORITHM and the GOTOs are sent ahead as a chain
  Trajectory,       ///< TRAJECTORY to=GOALS [compliant=yes] [speed_m_s=] [limit=] [dwell_s=]: plan, preview, send, run
  InvokeAlgorithm,  ///< INVOKE_ALGORITHM NAME [k=v ...] [timeout_s=]
  Request,          ///< REQUEST joints|wrench|tool|status|trajectories
  Camera,           ///< CAMERA NAME [action=select|point|grab] [pan_deg=] [tilt_deg=] [focal_px=]
  GotoJoint,        ///< GOTO_JOINT q=.. | q_deg=.. | start [speed=]
  GotoCart,         ///< GOTO_CART tag=NAME | xyz_m=x,y,z [rpy_deg=r,p,y] [speed=]
};
const char* to_string(Op op) noexcept;  ///< the command word, e.g. "INVOKE_ALGORITHM"
/// True for the commands sent to the robot.
bool is_remote(Op op) noexcept;

/// The remote's algorithms (INVOKE_ALGORITHM): guarded_move, insert, latch,
/// unlatch, loosen, tighten, pull_out, tare (re-zero the wrist F/T sensor).
const std::vector<std::string>& algorithm_names();

/// One value as written, with where it starts.
struct Value {
  std::string text;
  int column = 0;  ///< 1-based column of the value's first character
};

struct Command {
  Op op = Op::Request;
  int line = 0;    ///< 1-based
  int column = 0;  ///< of the command word
  std::string text;  ///< the command as written, without the comment, trimmed
  std::string note;  ///< the trailing comment, trimmed ("" when none)
  std::vector<Value> positional;
  std::map<std::string, Value> named;  ///< key -> value (each key at most once)

  bool has(const std::string& key) const { return named.count(key) != 0; }
  /// The value of `key` as text, or `fallback` when absent.
  std::string text_or(const std::string& key, const std::string& fallback) const;
  /// A number already checked by the parser, or `fallback` when absent.
  double number_or(const std::string& key, double fallback) const;
  /// A comma list of numbers already checked by the parser (empty when absent).
  std::vector<double> numbers(const std::string& key) const;
  /// A comma list of names (empty when absent).
  std::vector<std::string> names(const std::string& key) const;
  /// yes/true/1 -> true, no/false/0 -> false, absent -> fallback.
  bool flag_or(const std::string& key, bool fallback) const;
  /// For INVOKE_ALGORITHM: the algorithm's parameters (every key except timeout_s).
  std::vector<std::pair<std::string, double>> parameters() const;
};

struct Script {
  std::string file;  ///< for messages
  std::vector<Command> commands;
};

/// Parses script text. `file` names it in messages. Throws ScriptError at the
/// first error: unknown command, unknown or repeated key, missing or extra
/// values, a value of the wrong type.
Script parse_script(const std::string& text, const std::string& file);
/// Reads and parses a file (InputError "cannot open script" when unreadable).
Script load_script(const std::string& path);

/// What the configuration allows; empty sets are not checked.
struct ScriptContext {
  std::set<std::string> tags;     ///< the object's tag frames (TRAJECTORY, PREVIEW, TAG, GOTO_CART)
  std::set<std::string> cameras;  ///< VIDEO, CAMERA, CALIBRATE, LOCALIZE
  std::set<std::string> objects;  ///< OBJECT
  int joints = 0;                 ///< GOTO_JOINT length (0: not checked)
  std::vector<double> lower_rad, upper_rad;  ///< GOTO_JOINT limits (empty: not checked)
};

/// Checks names and joint vectors against the configuration; throws
/// ScriptError at the offending value ("unknown tag 'x' (tags: a, b)",
/// "unknown camera 'x' (cameras: ...)", "q has 6 values but the arm has 7 joints",
/// "q: joint4 = 3.1 rad is outside its limits [-2.79, 2.79]").
void check_script(const Script& script, const ScriptContext& context);

/// One trajectory goal of to=: a tag (or `start`), and the move kind.
struct GoalSpec {
  std::string name;
  bool linear = false;
  int column = 0;
};
/// Splits to=TAG[:linear|:joint],... (the parser has checked its syntax).
std::vector<GoalSpec> goals_of(const Command& command);

}  // namespace foresight::script

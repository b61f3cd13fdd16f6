// The task script parser and checker: good scripts parse to the right
// commands and values; every bad input fails with its exact message naming
// the line and column.
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <cstdio>

#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/script/script.hpp"

namespace foresight::script {
namespace {

std::string error_of(const std::string& text, const ScriptContext* ctx = nullptr) {
  try {
    const Script s = parse_script(text, "t.task");
    if (ctx != nullptr) check_script(s, *ctx);
  } catch (const ScriptError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(ScriptParser, ParsesCommandsValuesNotesAndColumns) {
  const Script s = parse_script(
      "# a comment line\n"
      "\n"
      "  graphics hidden\n"
      "VIDEO oblique   # the view\n"
      "TRAJECTORY to=approach_20cm,hole_entrance:linear compliant=yes speed_m_s=0.02\n"
      "INVOKE_ALGORITHM insert depth_m=0.06 force_n=40 timeout_s=30\n"
      "GOTO_JOINT q_deg=0,10,0,-90,0,45,0 speed=0.3\n"
      "GOTO_JOINT start\n"
      "GOTO_CART xyz_m=0.8,0,0.5 rpy_deg=180,0,0\n"
      "REQUEST wrench\n"
      "CAMERA side action=point pan_deg=-5 tilt_deg=2.5\n"
      "GRAB\nRELEASE\n",
      "t.task");
  ASSERT_EQ(s.commands.size(), 11u);
  const Command& g = s.commands[0];
  EXPECT_EQ(g.op, Op::Graphics);
  EXPECT_EQ(g.line, 3);
  EXPECT_EQ(g.column, 3);
  EXPECT_EQ(g.text, "graphics hidden");
  EXPECT_EQ(g.positional.at(0).text, "hidden");
  EXPECT_EQ(g.positional.at(0).column, 12);
  EXPECT_FALSE(is_remote(g.op));

  EXPECT_EQ(s.commands[1].note, "the view");
  EXPECT_EQ(s.commands[1].text, "VIDEO oblique");

  const Command& t = s.commands[2];
  EXPECT_EQ(t.op, Op::Trajectory);
  EXPECT_TRUE(is_remote(t.op));
  EXPECT_TRUE(t.flag_or("compliant", false));
  EXPECT_DOUBLE_EQ(t.number_or("speed_m_s", 0.05), 0.02);
  EXPECT_DOUBLE_EQ(t.number_or("limit", 0.5), 0.5);
  const auto goals = goals_of(t);
  ASSERT_EQ(goals.size(), 2u);
  EXPECT_EQ(goals[0].name, "approach_20cm");
  EXPECT_FALSE(goals[0].linear);
  EXPECT_EQ(goals[0].column, 15);
  EXPECT_EQ(goals[1].name, "hole_entrance");
  EXPECT_TRUE(goals[1].linear);
  EXPECT_EQ(goals[1].column, 29);

  const Command& a = s.commands[3];
  EXPECT_EQ(a.positional.at(0).text, "insert");
  EXPECT_DOUBLE_EQ(a.number_or("timeout_s", 0), 30);
  const auto params = a.parameters();
  ASSERT_EQ(params.size(), 2u);  // timeout_s is not a parameter; sorted by name
  EXPECT_EQ(params[0].first, "depth_m");
  EXPECT_DOUBLE_EQ(params[0].second, 0.06);
  EXPECT_EQ(params[1].first, "force_n");
  EXPECT_DOUBLE_EQ(params[1].second, 40);

  EXPECT_EQ(s.commands[4].numbers("q_deg"), (std::vector<double>{0, 10, 0, -90, 0, 45, 0}));
  EXPECT_DOUBLE_EQ(s.commands[4].number_or("speed", 0.5), 0.3);
  EXPECT_EQ(s.commands[5].positional.at(0).text, "start");
  EXPECT_EQ(s.commands[6].numbers("xyz_m"), (std::vector<double>{0.8, 0, 0.5}));
  EXPECT_EQ(s.commands[7].op, Op::Request);
  EXPECT_EQ(s.commands[8].text_or("action", "select"), "point");
  EXPECT_EQ(s.commands[9].op, Op::Grab);
  EXPECT_EQ(s.commands[10].op, Op::Release);
  EXPECT_STREQ(to_string(Op::InvokeAlgorithm), "INVOKE_ALGORITHM");
}

TEST(ScriptParser, SyntaxErrorsNameLineAndColumn) {
  EXPECT_EQ(error_of("VIDEO side\n  TRAJECTRY to=stow\n"),
            "t.task:2:3: unknown command 'TRAJECTRY' (commands: GRAPHICS, VIDEO, OBJECT, FRAME, TAG, GRAB, RELEASE, WAIT, "
            "PREVIEW, CALIBRATE, LOCALIZE, CHECK, TRAJECTORY, INVOKE_ALGORITHM, REQUEST, CAMERA, GOTO_JOINT, GOTO_CART)");
  EXPECT_EQ(error_of("TRAJECTORY to=stow sped=0.1\n"),
            "t.task:1:20: TRAJECTORY: unknown key 'sped' (keys: to, compliant, speed_m_s, limit, dwell_s)");
  EXPECT_EQ(error_of("TRAJECTORY compliant=yes\n"), "t.task:1:25: TRAJECTORY: missing to=");
  EXPECT_EQ(error_of("TRAJECTORY to=stow compliant=maybe\n"),
            "t.task:1:30: TRAJECTORY compliant: 'maybe' is not yes or no");
  EXPECT_EQ(error_of("TRAJECTORY to=stow,hole_entrance:curved\n"),
            "t.task:1:34: TRAJECTORY to: 'hole_entrance:curved': the move kind after ':' must be linear or joint");
  EXPECT_EQ(error_of("TRAJECTORY to=start:linear\n"),
            "t.task:1:15: TRAJECTORY to: 'start' is a joint-space goal; it cannot be linear");
  EXPECT_EQ(error_of("TRAJECTORY to=stow limit=1.5\n"), "t.task:1:26: TRAJECTORY limit must be in (0, 1], not 1.5");
  EXPECT_EQ(error_of("TRAJECTORY to=stow to=start\n"), "t.task:1:20: TRAJECTORY: to is given twice");
  EXPECT_EQ(error_of("INVOKE_ALGORITHM screw\n"),
            "t.task:1:18: INVOKE_ALGORITHM algorithm: 'screw' is not one of guarded_move, insert, latch, unlatch, "
            "loosen, tighten, pull_out, tare, identify_payload");
  EXPECT_EQ(error_of("INVOKE_ALGORITHM\n"),
            "t.task:1:17: INVOKE_ALGORITHM: missing algorithm (guarded_move | insert | latch | unlatch | loosen | "
            "tighten | pull_out | tare | identify_payload)");
  EXPECT_EQ(error_of("INVOKE_ALGORITHM insert depth_m=6cm\n"),
            "t.task:1:33: INVOKE_ALGORITHM depth_m: '6cm' is not a finite number");
  EXPECT_EQ(error_of("INVOKE_ALGORITHM insert timeout_s=-1\n"),
            "t.task:1:35: INVOKE_ALGORITHM timeout_s must be > 0, not -1");
  EXPECT_EQ(error_of("INVOKE_ALGORITHM latch depth_m=\n"), "t.task:1:24: INVOKE_ALGORITHM: depth_m= has no value");
  EXPECT_EQ(error_of("INVOKE_ALGORITHM latch =3\n"), "t.task:1:24: INVOKE_ALGORITHM: '=3' has no key before '='");
  EXPECT_EQ(error_of("REQUEST everything\n"),
            "t.task:1:9: REQUEST what: 'everything' is not one of joints, wrench, tool, status, trajectories");
  EXPECT_EQ(error_of("REQUEST joints wrench\n"), "t.task:1:16: REQUEST: unexpected extra value 'wrench'");
  EXPECT_EQ(error_of("GRAB now\n"), "t.task:1:6: GRAB takes no positional value, got 'now'");
  EXPECT_EQ(error_of("RELEASE x=1\n"), "t.task:1:9: RELEASE: unknown key 'x' (it takes none)");
  EXPECT_EQ(error_of("GOTO_JOINT q=0,0.1,abc,0\n"),
            "t.task:1:20: GOTO_JOINT q: element 3 ('abc') is not a finite number");
  EXPECT_EQ(error_of("GOTO_JOINT speed=0.5\n"), "t.task:1:21: GOTO_JOINT: missing the target: q=, q_deg= or start");
  EXPECT_EQ(error_of("GOTO_JOINT start q=0,0,0,0,0,0,0\n"),
            "t.task:1:20: GOTO_JOINT: give one target: q=, q_deg= or start");
  EXPECT_EQ(error_of("GOTO_CART xyz_m=0.8,0\n"), "t.task:1:17: GOTO_CART xyz_m needs 3 numbers, not 2");
  EXPECT_EQ(error_of("GOTO_CART tag=stow xyz_m=1,2,3\n"),
            "t.task:1:26: GOTO_CART: give tag= or xyz_m=, not both");
  EXPECT_EQ(error_of("GOTO_CART tag=stow rpy_deg=0,0,0\n"),
            "t.task:1:28: GOTO_CART: rpy_deg= goes with xyz_m=, not tag=");
  EXPECT_EQ(error_of("GOTO_CART speed=0.5\n"), "t.task:1:20: GOTO_CART: missing the target: tag= or xyz_m=");
  EXPECT_EQ(error_of("CAMERA side pan_deg=5 side\n"),
            "t.task:1:23: CAMERA: 'side' must come before the key=value options");
  EXPECT_EQ(error_of("VIDEO 3d\n"), "t.task:1:7: VIDEO camera: '3d' is not a name");
  EXPECT_EQ(error_of("GRAPHICS \x01wire\n"), "t.task:1:10: unexpected control character");
  EXPECT_EQ(error_of("GRAPHICS\n"), "t.task:1:9: GRAPHICS: missing mode (wire | solid | hidden | ghost | off)");
}

TEST(ScriptParser, ErrorCarriesLineColumnAndMessage) {
  try {
    parse_script("\n\nTAG\n", "x.task");
    FAIL() << "no error";
  } catch (const ScriptError& e) {
    EXPECT_EQ(e.line(), 3);
    EXPECT_EQ(e.column(), 4);
    EXPECT_EQ(e.message(), "TAG: missing tag");
    EXPECT_EQ(e.file(), "x.task");
  }
  EXPECT_THROW(load_script("/nonexistent/x.task"), InputError);
  try {
    load_script("/nonexistent/x.task");
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/nonexistent/x.task: cannot open script");
  }
}

ScriptContext project_context() {
  const RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  const ObjectModel object = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  ScriptContext ctx;
  for (const auto& [name, T] : object.tags) ctx.tags.insert(name);
  ctx.objects.insert(object.name);
  ctx.cameras = {"side", "oblique", "overhead_wide", "overhead_zoom"};
  ctx.joints = robot.dof();
  for (const auto& l : robot.limits()) {
    ctx.lower_rad.push_back(l.lower_rad);
    ctx.upper_rad.push_back(l.upper_rad);
  }
  return ctx;
}

TEST(ScriptCheck, NamesAndJointsAgainstTheConfiguration) {
  const ScriptContext ctx = project_context();
  EXPECT_EQ(error_of("TRAJECTORY to=approach_20cm,hole_entance:linear\n", &ctx),
            "t.task:1:29: unknown tag 'hole_entance' (tags: approach_20cm, hole_entrance, insert_start, pulled_out_5cm, stow, "
            "tool_inserted, withdrawn_15cm)");
  EXPECT_EQ(error_of("\nVIDEO front\n", &ctx),
            "t.task:2:7: unknown camera 'front' (cameras: oblique, overhead_wide, overhead_zoom, side)");
  EXPECT_EQ(error_of("CALIBRATE cameras=side,top\n", &ctx),
            "t.task:1:24: unknown camera 'top' (cameras: oblique, overhead_wide, overhead_zoom, side)");
  EXPECT_EQ(error_of("OBJECT satellite\n", &ctx), "t.task:1:8: unknown object 'satellite' (objects: oru)");
  EXPECT_EQ(error_of("GOTO_CART tag=nowhere\n", &ctx),
            "t.task:1:15: unknown tag 'nowhere' (tags: approach_20cm, hole_entrance, insert_start, pulled_out_5cm, stow, "
            "tool_inserted, withdrawn_15cm)");
  EXPECT_EQ(error_of("CHECK insert hole=hole_entance\n", &ctx),
            "t.task:1:19: unknown tag 'hole_entance' (tags: approach_20cm, hole_entrance, insert_start, pulled_out_5cm, stow, "
            "tool_inserted, withdrawn_15cm)");
  EXPECT_EQ(error_of("CHECK insert tag=insert_start hole=hole_entrance min_p=0.995 depth_m=0.065\n", &ctx), "(no error)");
  EXPECT_EQ(error_of("GOTO_JOINT q=0,0,0\n", &ctx), "t.task:1:14: q has 3 values but the arm has 7 joints");
  EXPECT_EQ(error_of("GOTO_JOINT q_deg=0,0,0,500,0,0,0\n", &ctx),
            "t.task:1:24: q_deg: joint4 = 500 deg is outside its limits [" +
                [&] {
                  char b[64];
                  std::snprintf(b, sizeof b, "%.2f, %.2f", ctx.lower_rad[3] * 180 / M_PI,
                                ctx.upper_rad[3] * 180 / M_PI);
                  return std::string(b);
                }() +
                "] deg");
  EXPECT_EQ(error_of("GOTO_JOINT q=0,0,0,0,0,0,0\nTRAJECTORY to=start\n", &ctx), "(no error)");
}

TEST(ScriptCheck, TheChangeoutScriptHasThePapersSeventeenSteps) {
  const Script s = load_script(FORESIGHT_CONFIG_DIR "/scripts/oru_changeout.task");
  check_script(s, project_context());
  // The notes number the paper's steps 1..17, in order.
  int expected = 1;
  for (const Command& c : s.commands) {
    if (c.note.empty() || !std::isdigit(static_cast<unsigned char>(c.note[0]))) continue;
    EXPECT_EQ(std::stoi(c.note), expected) << c.text;
    ++expected;
  }
  EXPECT_EQ(expected, 18);
  // Steps 1 and 2 (calibrate, localize) are the ground's; 3..17 go to the robot.
  for (const Command& c : s.commands) {
    if (c.note.empty() || !std::isdigit(static_cast<unsigned char>(c.note[0]))) continue;
    EXPECT_EQ(is_remote(c.op), std::stoi(c.note) >= 3) << c.text;
  }
}

}  // namespace
}  // namespace foresight::script

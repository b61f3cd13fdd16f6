// `foresight run`'s command runner (script_runner.hpp). Registers no command.
#include "foresight/session/script_runner.hpp"

#include "foresight/session/insert_check.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/atomic_file.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <thread>

#include "foresight/common/plan.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/common/format.hpp"
#include "foresight/session/link_session.hpp"
#include "foresight/session/processes.hpp"
#include "foresight/session/operations.hpp"

namespace foresight::session {

namespace {

using Clock = std::chrono::steady_clock;
using script::CommandState;
using script::Op;
using script::Outcome;

std::string joints_text(const Eigen::VectorXd& q) {
  std::string out;
  char buf[32];
  for (Eigen::Index i = 0; i < q.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%.9g", q[i]);
    out += (i ? "," : "") + std::string(buf);
  }
  return out;
}

Outcome failed(const std::string& message, Clock::time_point t0) {
  return {CommandState::Failed, message, since(t0)};
}
Outcome done(const std::string& message, Clock::time_point t0) {
  return {CommandState::Completed, message, since(t0)};
}

Outcome from_result(protocol::CommandKind kind, const ground_link::CommandResult& r, Clock::time_point t0) {
  Outcome o;
  o.seconds = since(t0);
  o.message = result_line(kind, r);
  if (r.succeeded()) o.state = CommandState::Completed;
  else if (r.finished && r.state == protocol::AckState::Canceled) o.state = CommandState::Canceled;
  else o.state = CommandState::Failed;
  return o;
}

}  // namespace

ScriptRunner::ScriptRunner(RunSettings settings, std::unique_ptr<ground_link::GroundLink> link)
    : s_(std::move(settings)),
      link_(std::move(link)),
      model_(RobotModel::from_file(s_.robot)),
      object_(ObjectModel::from_file(s_.object)),
      scene_(Scene::from_file(s_.scene)),
      ws_(model_) {
  std::filesystem::create_directories(s_.work_dir);
  journal_.open(path("run.jsonl"), std::ios::app);
  if (!journal_) throw InputError(path("run.jsonl"), "cannot write the journal");
  if (s_.object_pose == "scene") {
    base_T_object_ = scene_.base_T_object;
    pose_source_ = s_.scene + " (the work site's true pose)";
  } else if (!s_.object_pose.empty()) {
    base_T_object_ = localization::read_object_pose_json(s_.object_pose);
    pose_source_ = pose_file_ = s_.object_pose;
  }
  if (link_) {
    for (const auto kind : {protocol::CommandKind::TakeControl, protocol::CommandKind::Recover}) {
      if (kind == protocol::CommandKind::Recover && !s_.recover) continue;
      const auto r = send_and_wait(*link_, kind, protocol::NoPayload{}, link_->timeout_for(5.0));
      if (!r.succeeded()) throw LinkFailure(result_line(kind, r));
      say(result_line(kind, r));
    }
    const auto j = wait_joints(*link_, 10.0);
    if (!j) throw LinkFailure("no joint report from the remote within 10 s");
    q_ = require_joints(j->value, model_);
  } else {
    if (s_.q_from.size() != model_.dof()) throw std::invalid_argument("--dry-run needs --from or --from-deg");
    q_ = s_.q_from;
  }
  q_start_ = q_;
}

ScriptRunner::~ScriptRunner() {
  if (!link_) return;
  try {  // give control back so another station (or the next run) may take it
    send_and_wait(*link_, protocol::CommandKind::ReleaseControl, protocol::NoPayload{}, link_->timeout_for(0.0));
  } catch (const std::exception&) {
  }
}

script::ScriptContext ScriptRunner::context_for(const RobotModel& model, const ObjectModel& object,
                                                const Scene& scene) {
  script::ScriptContext ctx;
  for (const auto& [name, T] : object.tags) ctx.tags.insert(name);
  for (const auto& [name, cam] : scene.cameras) ctx.cameras.insert(name);
  ctx.objects.insert(object.name);
  ctx.joints = model.dof();
  for (const auto& l : model.limits()) {
    ctx.lower_rad.push_back(l.lower_rad);
    ctx.upper_rad.push_back(l.upper_rad);
  }
  return ctx;
}

std::string ScriptRunner::path(const std::string& name) const { return s_.work_dir + "/" + name; }

std::string ScriptRunner::ground_yaml() const { return s_.ground.empty() ? default_config("ground.yaml") : s_.ground; }

void ScriptRunner::say(const std::string& line) const { (s_.quiet ? std::cerr : std::cout) << "    " << line << "\n"; }

void ScriptRunner::journal(const script::Command& c, const Outcome& o, nlohmann::json extra) {
  extra["line"] = c.line;
  extra["command"] = c.text;
  extra["outcome"] = script::to_string(o.state);
  extra["message"] = o.message;
  extra["seconds"] = o.seconds;
  extra["dry_run"] = s_.dry_run;
  journal_ << json_text(extra) << "\n" << std::flush;
}

nlohmann::json ScriptRunner::update_arm(const std::vector<double>& reported, const Eigen::VectorXd& predicted,
                                        bool completed) {
  nlohmann::json j;
  if (static_cast<int>(reported.size()) != model_.dof()) {
    j["update"] = "no final joints reported; the simulated arm keeps the predicted ones";
    q_ = predicted;
    return j;
  }
  const Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(reported.data(), model_.dof());
  const double dq = (q - predicted).cwiseAbs().maxCoeff();
  const Pose a = forward_kinematics(model_, ws_, predicted);
  const Pose b = forward_kinematics(model_, ws_, q);
  const double dp = (a.translation() - b.translation()).norm();
  const double dr = Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
  q_ = q;  // the paper's update step
  char buf[200];
  if (completed)
    std::snprintf(buf, sizeof buf,
                  "update: reported final joints differ from the predicted by %.4f deg max; tool tip %.2f mm, %.3f deg",
                  dq * 180.0 / M_PI, dp * 1e3, dr * 180.0 / M_PI);
  else
    std::snprintf(buf, sizeof buf,
                  "update: the motion ended short of its planned end: the arm stopped %.4f deg max, tool tip %.2f mm "
                  "from it (the reported joints are the arm's now)",
                  dq * 180.0 / M_PI, dp * 1e3);
  j["completed"] = completed;
  say(buf);
  j["predicted_final_q_rad"] = std::vector<double>(predicted.data(), predicted.data() + predicted.size());
  j["reported_final_q_rad"] = reported;
  j["max_joint_difference_rad"] = dq;
  j["tip_position_difference_m"] = dp;
  j["tip_rotation_difference_deg"] = dr * 180.0 / M_PI;
  return j;
}

Outcome ScriptRunner::run(const script::Command& c, const std::function<bool()>& interrupted) {
  pending_journal_ = nlohmann::json::object();
  Outcome o;
  try {
    if (recover_before_next_ && link_ && script::is_remote(c.op)) {
      // The controlled stop may still be running: RECOVER is Busy until it ends (bounded).
      ground_link::CommandResult r;
      const auto deadline = Clock::now() + std::chrono::seconds(10);
      do {
        r = send_and_wait(*link_, protocol::CommandKind::Recover, protocol::NoPayload{}, link_->timeout_for(5.0));
        if (r.succeeded() || r.code != protocol::Reason::Busy) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
      } while (Clock::now() < deadline);
      say(result_line(protocol::CommandKind::Recover, r) + " (after the cancel)");
      if (!r.succeeded()) throw LinkFailure(result_line(protocol::CommandKind::Recover, r));
      recover_before_next_ = false;
      // CANCELED carried the joints where the stop began; the arm came to
      // rest a little further on. Plan the next motion from where it holds
      // (the report after RECOVER's ack was sent once the stop had ended).
      if (const auto j = wait_joints(*link_, 5.0))
        if (auto q = joints_of(j->value, model_)) q_ = std::move(*q);
    }
    if (c.op == Op::Trajectory || c.op == Op::Preview) o = trajectory(c, c.op == Op::Trajectory, interrupted);
    else if (script::is_remote(c.op)) o = remote(c, interrupted);
    else o = local(c, interrupted);
  } catch (const std::exception& e) {  // a bad file, a link error: the command fails, the run stops here
    o = {CommandState::Failed, e.what(), 0.0};
  }
  if (o.state == CommandState::Canceled && link_ && script::is_remote(c.op)) recover_before_next_ = true;
  journal(c, o, pending_journal_);
  return o;
}

Outcome ScriptRunner::local(const script::Command& c, const std::function<bool()>& interrupted) {
  const auto t0 = Clock::now();
  switch (c.op) {
    case Op::Graphics: graphics_ = c.positional[0].text; return done("graphics " + graphics_, t0);
    case Op::Video: video_camera_ = c.positional[0].text; return done("video from camera " + video_camera_, t0);
    case Op::Frame: frame_ = c.positional[0].text; return done("reference frame " + frame_, t0);
    case Op::Tag: tag_ = c.positional[0].text; return done("tag " + tag_ + " selected", t0);
    case Op::Grab: grabbed_ = true; return done("the object's graphics move with the tool", t0);
    case Op::Release: grabbed_ = false; return done("the object's graphics stay where they are", t0);
    case Op::Check: return check(c);
    case Op::Wait:  // drive() settled every command sent ahead before this one
      return done(s_.chain ? "the chain ended here: every command sent ahead has ended" : "nothing sent ahead", t0);
    case Op::Object:
      if (c.has("pose")) {
        base_T_object_ = localization::read_object_pose_json(c.text_or("pose", ""));
        pose_source_ = pose_file_ = c.text_or("pose", "");
      }
      return done("object " + c.positional[0].text + (pose_source_.empty() ? "" : ", pose from " + pose_source_), t0);
    case Op::Calibrate: {
      std::vector<std::string> cams = c.names("cameras");
      if (cams.empty()) cams = scene_.camera_order;
      const std::string points = c.text_or("points", path("arm_clicks.csv"));
      const std::string out = s_.cameras.empty() ? path("cameras.yaml") : s_.cameras;
      // One belief about the arm model: the link sigma CHECK insert uses
      // (ground.yaml contact_check) enters the calibration too, so the
      // cameras carry their sensitivity to the links and the check sees the
      // same link error move cameras and tool together.
      const double arm_link_sigma_m = contact_check::load_contact_check_config(ground_yaml()).arm_link_sigma_m;
      for (const auto& cam : cams) {
        if (interrupted && interrupted()) return {CommandState::Canceled, "calibration of " + cam + " interrupted", since(t0)};
        CalibrateRequest request;
        request.points = points;
        request.camera = cam;
        request.out = out;
        request.robot = s_.robot;
        request.arm_link_sigma_m = arm_link_sigma_m;
        try {
          add_camera(out, cam, calibrate_from_clicks(request));
        } catch (const std::exception& e) {
          return failed("calibrate " + cam + ": " + e.what(), t0);
        }
        say("calibrated " + cam + " -> " + out);
      }
      s_.cameras = out;
      return done("calibrated " + std::to_string(cams.size()) + " camera(s) into " + out, t0);
    }
    case Op::Localize: {
      if (s_.cameras.empty()) return failed("no calibrated cameras: CALIBRATE first or give --cameras", t0);
      const std::string points = c.text_or("points", path("oru_clicks.csv"));
      const std::string out = path("localize.json");
      LocalizeRequest request;
      request.points = points;
      request.cameras = s_.cameras;
      request.object = s_.object;
      request.views = c.text_or("views", "");
      try {
        write_file_atomic(out, localized_json(localize_from_clicks(request)).dump(2) + "\n");
      } catch (const std::exception& e) {
        return failed(std::string("localize: ") + e.what(), t0);
      }
      base_T_object_ = localization::read_object_pose_json(out);
      pose_source_ = pose_file_ = out;
      const Eigen::Vector3d p = base_T_object_->translation();
      char buf[160];
      std::snprintf(buf, sizeof buf, "object at %.4f %.4f %.4f m (base) -> %s", p.x(), p.y(), p.z(), out.c_str());
      return done(buf, t0);
    }
    default:
      return failed(std::string("not a local command: ") + script::to_string(c.op), t0);
  }
}

Outcome ScriptRunner::check(const script::Command& c) {
  const auto t0 = Clock::now();
  if (!base_T_object_) return failed("no object pose: LOCALIZE first, OBJECT oru pose=FILE, or --object-pose", t0);
  InsertCheckContext ctx;
  contact_check::ObjectEstimate est;
  if (!pose_file_.empty()) {  // else the scene's true pose: no estimation error
    try {
      est = estimate_of(pose_file_, ctx);
    } catch (const InputError& e) {
      return failed(std::string("CHECK insert: ") + e.what(), t0);
    }
  }
  est.base_T_object = *base_T_object_;
  ctx.object = &object_;
  ctx.robot = &model_;
  ctx.config = contact_check::load_contact_check_config(ground_yaml());
  if (c.has("min_p")) ctx.config.min_p_success = c.number_or("min_p", ctx.config.min_p_success);
  if (!s_.cameras.empty() && std::filesystem::exists(s_.cameras))
    for (const auto& [name, rec] : camera::load_cameras(s_.cameras)) ctx.cameras[name] = rec.camera;
  InsertStep step;
  step.tag = c.text_or("tag", step.tag);
  step.hole_tag = c.text_or("hole", step.hole_tag);
  step.params.depth_m = c.number_or("depth_m", step.params.depth_m);
  step.params.spiral_max_radius_m = c.number_or("spiral_max_radius_m", step.params.spiral_max_radius_m);
  const InsertCheck r = check_insert(est, step, ctx);
  const contact_check::InsertPrediction& p = r.prediction;
  pending_journal_["check"] = insert_check_json(r);
  char buf[256];
  std::snprintf(buf, sizeof buf, "CHECK insert: %s, P(success) %.4f %s %.4f (95%%: lateral %.1f mm, axial %.1f mm, tilt %.2f deg)%s",
                contact_check::verdict(p), p.p_success, p.go ? ">=" : "<", p.min_p_success, p.lateral95_m * 1e3,
                p.axial95_m * 1e3, p.tilt95_deg, pose_file_.empty() ? " (the true pose: no estimation error)" : "");
  if (p.go) return done(buf, t0);
  std::string advice;
  for (const std::string& a : r.advice) advice += "; " + a;
  const bool overridden =
      std::find(s_.override_checks.begin(), s_.override_checks.end(), "insert") != s_.override_checks.end();
  pending_journal_["overridden"] = overridden;
  if (overridden) {
    say(std::string(buf) + advice);
    return done(std::string(buf) + ": OVERRIDDEN by the operator (--override-check insert)", t0);
  }
  return failed(std::string(buf) + advice + " (to go on anyway: --override-check insert)", t0);
}

Outcome ScriptRunner::trajectory(const script::Command& c, bool send, const std::function<bool()>& interrupted) {
  const auto t0 = Clock::now();
  if (!base_T_object_) return failed("no object pose: LOCALIZE first, OBJECT oru pose=FILE, or --object-pose", t0);
  std::vector<Goal> goals;
  for (const auto& g : script::goals_of(c)) {
    Goal goal;
    goal.name = g.name;
    goal.kind = g.linear ? SegmentKind::Linear : SegmentKind::Joint;
    if (g.name == "start") {
      goal.is_pose = false;
      goal.q = q_start_;
    } else {
      goal.base_T_tip = *base_T_object_ * object_.tags.at(g.name);
    }
    goals.push_back(goal);
  }
  PlanOptions options;
  options.limit_fraction = c.number_or("limit", options.limit_fraction);
  options.tool_speed_m_s = c.number_or("speed_m_s", options.tool_speed_m_s);
  options.dwell_s = c.number_or("dwell_s", options.dwell_s);
  Plan plan;
  try {
    plan = plan_motion(model_, q_, goals, options);
  } catch (const PlanError& e) {
    return failed(std::string("not sent: ") + e.what(), t0);
  }
  const auto violations = validate(plan.trajectory, TrajectoryLimits::from_model(model_));
  if (!violations.empty())
    return failed("not sent: the path breaks " + std::to_string(violations.size()) + " rule(s): " + violations[0].message, t0);
  ++motion_count_;
  char stem[64];
  std::snprintf(stem, sizeof stem, "line%03d_%02d", c.line, motion_count_);
  const std::string csv = path(std::string(stem) + ".csv");
  write_trajectory_csv(csv, plan.trajectory);
  const std::string hash = to_hex(trajectory_hash(plan.trajectory));
  char buf[256];
  std::snprintf(buf, sizeof buf, "planned %zu segment(s), %.2f s, %d samples -> %s", plan.segments.size(),
                plan.trajectory.duration_s(), plan.trajectory.samples(), csv.c_str());
  say(buf);
  pending_journal_["trajectory"] = csv;
  pending_journal_["sha256"] = hash;
  pending_journal_["duration_s"] = plan.trajectory.duration_s();
  if (s_.preview) {
    const std::string camera = c.text_or("camera", video_camera_.empty() ? scene_.camera_order.front() : video_camera_);
    if (s_.cameras.empty()) return failed("no calibrated cameras for the preview: CALIBRATE first, --cameras, or --no-preview", t0);
    std::string image = s_.image;
    if (image.empty()) {  // the synthetic camera stands in for the live video
      image = path(std::string(stem) + "_video_" + camera + ".png");
      SynthRequest frame;
      frame.camera = camera;
      frame.joints = joints_text(q_);
      frame.out = image;
      frame.scene = s_.scene;
      frame.robot = s_.robot;
      frame.object = s_.object;
      try {
        synth_frame(frame);
      } catch (const std::exception& e) {
        return failed(std::string("synth (the preview's video frame): ") + e.what(), t0);
      }
    }
    const std::string video = path(std::string(stem) + "_preview.mp4");
    const std::string sheet = path(std::string(stem) + "_sheet.png");
    PreviewRequest request;
    request.trajectory = csv;
    request.cameras = s_.cameras;
    request.camera = camera;
    request.image = image;
    request.out = video;
    request.sheet = sheet;
    request.speed = s_.preview_speed;
    request.robot = s_.robot;
    request.object = s_.object;
    request.scale_image = true;
    request.interrupted = interrupted;
    if (pose_source_ != "" && std::filesystem::exists(pose_source_)) request.object_pose = pose_source_;
    try {
      preview_trajectory(request);
    } catch (const preview::Interrupted&) {
      return {CommandState::Canceled, "preview interrupted", since(t0)};
    } catch (const std::exception& e) {
      return failed(std::string("not sent: preview: ") + e.what(), t0);
    }
    say("preview " + video + ", contact sheet " + sheet);
    pending_journal_["preview"] = video;
    pending_journal_["contact_sheet"] = sheet;
  }
  say("sha256 " + hash);
  const Eigen::VectorXd predicted = plan.trajectory.positions_rad.row(plan.trajectory.samples() - 1).transpose();
  if (!send) return done("previewed, not sent (sha256 " + hash.substr(0, 12) + ")", t0);
  if (s_.dry_run) {
    q_ = predicted;
    return done("dry run: not sent (sha256 " + hash.substr(0, 12) + ")", t0);
  }
  // Upload and run in one go: the RUN follows the chunks at once and the
  // remote starts it once the whole upload committed with this hash.
  protocol::RunTrajectory run;
  run.compliant = c.flag_or("compliant", false);
  const auto kind = protocol::CommandKind::Trajectory;
  if (s_.chain) {
    const auto sent = upload_and_run(*link_, plan.trajectory, run, chain_tail_);
    return send_ahead(c, kind, sent.command_id, sent.sent, plan.trajectory.duration_s() + sent.upload_wait_s,
                      predicted, "trajectory " + std::to_string(sent.upload.trajectory_id) + " with its RUN");
  }
  const auto sent = upload_and_run(*link_, plan.trajectory, run);
  pending_journal_["command_id"] = sent.command_id;
  say("sent trajectory " + std::to_string(sent.upload.trajectory_id) + " with its RUN (runs once the whole upload " +
      "is there with this hash; waits at most " + fixed(sent.upload_wait_s, 1) + " s for it)");
  const auto r = wait_or_abort(*link_, sent.command_id, sent.sent,
                               final_ack_timeout(*link_, plan.trajectory.duration_s() + sent.upload_wait_s, s_.timeout_s),
                               interrupted);
  auto up = sent.upload;
  link_->wait_upload(up, std::chrono::nanoseconds(0));  // its status came before the RUN started
  if (up.state == protocol::UploadState::Committed) {
    say("committed trajectory " + std::to_string(up.trajectory_id) + ": remote sha256 " + to_hex(up.remote_hash) +
        (up.remote_hash == up.local_hash ? " = local" : " != local"));
    pending_journal_["remote_sha256"] = to_hex(up.remote_hash);
  }
  Outcome o = from_result(kind, r, t0);
  if (r.finished)
    pending_journal_.update(update_arm(r.final_q_rad, predicted, r.state == protocol::AckState::Completed));
  return o;
}

Outcome ScriptRunner::remote(const script::Command& c, const std::function<bool()>& interrupted) {
  const auto t0 = Clock::now();
  protocol::Payload payload;
  protocol::CommandKind kind = protocol::CommandKind::Request;
  double expected_s = 0.0;
  std::optional<Eigen::VectorXd> predicted;
  switch (c.op) {
    case Op::InvokeAlgorithm: {
      protocol::InvokeAlgorithm inv;
      inv.name = c.positional[0].text;
      inv.timeout_s = c.number_or("timeout_s", 0.0);
      for (const auto& [k, v] : c.parameters()) inv.params.push_back({k, v});
      payload = inv;
      kind = protocol::CommandKind::InvokeAlgorithm;
      expected_s = inv.timeout_s > 0 ? inv.timeout_s : 60.0;
      break;
    }
    case Op::Request: {
      protocol::Request r;
      const std::string w = c.positional[0].text;
      r.what = w == "joints"   ? protocol::RequestWhat::JointState
               : w == "wrench" ? protocol::RequestWhat::Wrench
               : w == "tool"   ? protocol::RequestWhat::ToolState
               : w == "trajectories" ? protocol::RequestWhat::Trajectories
                                     : protocol::RequestWhat::Status;
      payload = r;
      break;
    }
    case Op::Camera: {
      protocol::CameraCommand cam;
      cam.camera = c.positional[0].text;
      const std::string a = c.text_or("action", "select");
      cam.action = a == "point" ? protocol::CameraAction::Point
                   : a == "grab" ? protocol::CameraAction::Grab
                                 : protocol::CameraAction::Select;
      cam.pan_rad = c.number_or("pan_deg", 0.0) * M_PI / 180.0;
      cam.tilt_rad = c.number_or("tilt_deg", 0.0) * M_PI / 180.0;
      cam.focal_px = c.number_or("focal_px", 0.0);
      payload = cam;
      kind = protocol::CommandKind::Camera;
      break;
    }
    case Op::GotoJoint: {
      protocol::GotoJoint g;
      Eigen::VectorXd q = q_start_;
      if (c.has("q") || c.has("q_deg")) {
        const bool deg = c.has("q_deg");
        const auto v = c.numbers(deg ? "q_deg" : "q");
        q = Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size())) * (deg ? M_PI / 180.0 : 1.0);
      }
      g.q_rad.assign(q.data(), q.data() + q.size());
      g.speed_fraction = c.number_or("speed", 0.5);
      payload = g;
      kind = protocol::CommandKind::GotoJoint;
      predicted = q;
      break;
    }
    case Op::GotoCart: {
      protocol::GotoCart g;
      g.frame = "lst_tip";
      if (c.has("tag")) {
        if (!base_T_object_) return failed("no object pose: LOCALIZE first, OBJECT oru pose=FILE, or --object-pose", t0);
        g.base_T_frame = *base_T_object_ * object_.tags.at(c.text_or("tag", ""));
      } else {
        const auto xyz = c.numbers("xyz_m");
        auto rpy = c.numbers("rpy_deg");
        if (rpy.empty()) rpy = {0, 0, 0};
        g.base_T_frame = make_pose(Eigen::Vector3d(xyz[0], xyz[1], xyz[2]),
                                   Eigen::Vector3d(rpy[0], rpy[1], rpy[2]) * M_PI / 180.0);
      }
      g.speed_fraction = c.number_or("speed", 0.5);
      payload = g;
      kind = protocol::CommandKind::GotoCart;
      break;
    }
    default:
      return failed(std::string("not a remote command: ") + script::to_string(c.op), t0);
  }
  if (kind == protocol::CommandKind::GotoJoint || kind == protocol::CommandKind::GotoCart) {
    // Plan the remote's path here first: its duration bounds the wait, and a
    // goal that cannot be planned is not sent.
    try {
      std::vector<double> q(q_.data(), q_.data() + q_.size());
      expected_s = planned_goto_duration_s(model_, q, payload);
    } catch (const PlanError& e) {
      return failed(std::string("not sent: ") + e.what(), t0);
    }
    if (!predicted) {  // GOTO_CART: the IK end point of the same plan
      const auto& gc = std::get<protocol::GotoCart>(payload);
      Goal goal;
      goal.kind = SegmentKind::Linear;
      goal.base_T_tip = gc.base_T_frame;
      PlanOptions options;
      options.limit_fraction = gc.speed_fraction;
      options.tool_speed_m_s = 0.1 * gc.speed_fraction;
      predicted = plan_motion(model_, q_, {goal}, options).segments.back().q_end;
    }
  }
  if (s_.dry_run) {
    if (predicted) q_ = *predicted;
    return done(std::string("dry run: ") + protocol::to_string(kind) + " not sent", t0);
  }
  if (s_.chain && chains(c)) {
    if (!predicted) predicted = c.op == Op::InvokeAlgorithm ? algorithm_end(c) : std::optional<Eigen::VectorXd>(q_);
    const auto sent = Clock::now();
    const auto id = link_->send(kind, payload, -1.0, chain_tail_);
    return send_ahead(c, kind, id, sent, expected_s, *predicted, protocol::to_string(kind));
  }
  const auto r = send_and_wait(*link_, kind, payload, final_ack_timeout(*link_, expected_s, s_.timeout_s), interrupted);
  pending_journal_["command_id"] = r.command_id;
  Outcome o = from_result(kind, r, t0);
  if (r.finished && !r.final_q_rad.empty()) {
    if (predicted)
      pending_journal_.update(update_arm(r.final_q_rad, *predicted, r.state == protocol::AckState::Completed));
    else q_ = Eigen::Map<const Eigen::VectorXd>(r.final_q_rad.data(), static_cast<Eigen::Index>(r.final_q_rad.size()));
  }
  return o;
}

bool ScriptRunner::chains(const script::Command& c) const {
  if (!s_.chain || !link_) return false;
  switch (c.op) {
    case Op::Trajectory:
    case Op::GotoJoint:
    case Op::GotoCart:
    case Op::Preview:
    case Op::Graphics:
    case Op::Video:
    case Op::Object:
    case Op::Frame:
    case Op::Tag:
    case Op::Grab:
    case Op::Release:
    case Op::Request: return true;  // the report once the chain got there (the remote queues it too)
    case Op::InvokeAlgorithm: {
      const std::string name = c.positional[0].text;
      if (name == "insert") return c.has("depth_m");
      if (name == "pull_out") return c.has("distance_m");
      return name != "guarded_move";  // it ends at a contact nobody can place in advance
    }
    default: return false;  // CALIBRATE, LOCALIZE, WAIT, CAMERA: the arm where it is now
  }
}

std::optional<Eigen::VectorXd> ScriptRunner::algorithm_end(const script::Command& c) {
  const std::string name = c.positional[0].text;
  double along_z = 0.0;
  if (name == "insert") along_z = c.number_or("depth_m", std::nan(""));
  else if (name == "pull_out") along_z = -c.number_or("distance_m", std::nan(""));
  else if (name == "guarded_move") return std::nullopt;
  if (!std::isfinite(along_z)) return std::nullopt;
  if (along_z == 0.0) return q_;  // latch, unlatch, loosen, tighten, tare, identify_payload: the arm holds (or returns)
  // The remote's task frame is the tool tip's at the start: the tip moves
  // along its own z axis with its orientation kept (a straight line).
  const Pose tip = forward_kinematics(model_, ws_, q_);
  Goal goal;
  goal.kind = SegmentKind::Linear;
  goal.base_T_tip = tip;
  goal.base_T_tip.translation() += tip.linear() * Eigen::Vector3d(0.0, 0.0, along_z);
  return plan_motion(model_, q_, {goal}, PlanOptions{}).segments.back().q_end;
}

Outcome ScriptRunner::send_ahead(const script::Command& c, protocol::CommandKind kind, std::uint64_t command_id,
                                 Clock::time_point sent, double expected_s, const Eigen::VectorXd& predicted,
                                 const std::string& what) {
  const std::uint64_t after = chain_tail_;
  pending_journal_["command_id"] = command_id;
  pending_journal_["after_command_id"] = after;
  sent_ahead_.push_back({c, kind, command_id, sent, expected_s, predicted, pending_journal_});
  chain_tail_ = command_id;
  q_ = predicted;  // the next step is planned from this one's planned end
  const std::string line = "sent " + what + " as command " + std::to_string(command_id) +
                           (after != 0 ? " after command " + std::to_string(after) : " (heads a chain)");
  say(line + "; not waited for: the next step starts from its planned end");
  return {CommandState::Sent, line, since(sent)};
}

void ScriptRunner::settle(const std::function<bool()>& interrupted,
                          const std::function<void(int line, const Outcome&)>& on_settled) {
  if (sent_ahead_.empty()) return;
  bool aborted = false;
  const auto abort_all = [&](const std::string& why) {
    if (aborted) return;
    aborted = true;
    protocol::Abort a;
    a.target_command_id = 0;  // what runs stops (category 2), every queued command is canceled
    a.category = protocol::StopCategory::Cat2;
    a.reason = why;
    link_->send(protocol::CommandKind::Abort, a);
    say("ABORT sent: " + why + " (it reaches the remote half a round trip from now)");
  };
  bool canceled = false;
  for (auto& a : sent_ahead_) {
    auto deadline = Clock::now() + final_ack_timeout(*link_, a.expected_s, s_.timeout_s);
    bool extended = false;
    ground_link::CommandResult r;
    while (true) {
      r = link_->wait_final(a.command_id, std::chrono::milliseconds(100));
      if (r.finished) break;
      if (!aborted && interrupted && interrupted()) abort_all("canceled by the operator: the chain stops here");
      if (Clock::now() >= deadline) {
        if (extended) break;
        abort_all("no final acknowledgement of command " + std::to_string(a.command_id) + " in time");
        deadline = Clock::now() + link_->timeout_for(5.0);
        extended = true;
      }
    }
    Outcome o = from_result(a.kind, r, a.sent);
    if (r.finished && !r.final_q_rad.empty())
      a.journal.update(update_arm(r.final_q_rad, a.predicted, r.state == protocol::AckState::Completed));
    a.journal["chained"] = true;
    say("line " + std::to_string(a.command.line) + ": " + o.message);
    journal(a.command, o, a.journal);
    canceled = canceled || o.state == CommandState::Canceled;
    on_settled(a.command.line, o);
  }
  sent_ahead_.clear();
  chain_tail_ = 0;
  if (canceled) recover_before_next_ = true;
}

}  // namespace foresight::session

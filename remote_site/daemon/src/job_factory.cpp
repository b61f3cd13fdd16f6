#include "foresight/daemon/job.hpp"

#include <cmath>

#include "foresight/common/format.hpp"
#include "foresight/common/plan.hpp"
#include "foresight/control/command.hpp"
#include "foresight/daemon/algorithm_params.hpp"

namespace foresight::daemon {

using protocol::CommandKind;
using protocol::Reason;

std::unique_ptr<Job> JobFactory::make(const protocol::Command& c, Reason* code, std::string* reason) const {
  auto job = std::make_unique<Job>();
  job->command = c;
  bool made = false;
  switch (c.kind) {
    case CommandKind::Trajectory:
      made = make_trajectory_job(std::get<protocol::RunTrajectory>(c.payload), *job, code, reason);
      break;
    case CommandKind::GotoJoint:
    case CommandKind::GotoCart:
      made = check_goto(c, code, reason);
      job->kind = JobKind::Goto;
      break;
    case CommandKind::InvokeAlgorithm:
      made = make_invoke_job(std::get<protocol::InvokeAlgorithm>(c.payload), *job, code, reason);
      break;
    case CommandKind::Recover:
      job->kind = JobKind::Recover;
      made = true;
      break;
    case CommandKind::Request:  // chained: the report once the chain got here
      job->kind = JobKind::Report;
      made = true;
      break;
    default:
      *code = Reason::Internal;
      *reason = std::string("no handler for ") + control::to_string(c.kind);
      break;
  }
  return made ? std::move(job) : nullptr;
}

bool JobFactory::make_trajectory_job(const protocol::RunTrajectory& p, Job& job, Reason* code,
                                     std::string* reason) const {
  if (!(p.start_tolerance_rad >= 0.0) || !std::isfinite(p.start_tolerance_rad) ||
      p.start_tolerance_rad > kMaxStartToleranceRad) {
    *code = Reason::BadArgument;
    *reason = printf_text("start_tolerance_rad %g out of range [0, ", p.start_tolerance_rad) +
              printf_text("%g] rad: a larger start offset would jump the arm; plan an approach segment (a "
                          "GOTO_JOINT to the first sample)",
                          kMaxStartToleranceRad);
    return false;
  }
  if (!(p.upload_wait_s >= 0.0) || !(p.upload_wait_s <= config_.max_upload_wait_s)) {
    *code = Reason::BadArgument;
    *reason = printf_text("upload_wait_s %g out of range [0, %g] s (controller.max_upload_wait_s)", p.upload_wait_s,
                          config_.max_upload_wait_s);
    return false;
  }
  job.kind = JobKind::Trajectory;
  job.compliant = p.compliant;
  job.start_tolerance_rad = p.start_tolerance_rad;
  if (const UploadStore::Committed* committed = uploads_.committed(p.trajectory_id))
    return attach_upload(job, *committed, code, reason);
  if (const std::string* refused = uploads_.refused(p.trajectory_id)) {
    *code = Reason::IncompleteUpload;
    *reason = "upload " + std::to_string(p.trajectory_id) + " was refused: " + *refused;
    return false;
  }
  if (p.upload_wait_s == 0.0) {
    *code = Reason::UnknownTrajectory;
    *reason = "no committed upload with id " + std::to_string(p.trajectory_id) +
              " (a RUN with upload_wait_s > 0 may overtake its upload)";
    return false;
  }
  // RUN overtook its upload (issue 29): held until the whole upload
  // committed with this hash, or failed at the deadline.
  job.awaiting_upload = p.trajectory_id;
  job.upload_deadline = Job::Clock::now() + std::chrono::duration_cast<Job::Clock::duration>(
                                                std::chrono::duration<double>(p.upload_wait_s));
  return true;
}

bool JobFactory::attach_upload(Job& job, const UploadStore::Committed& committed, Reason* code,
                               std::string* reason) const {
  const auto& run = std::get<protocol::RunTrajectory>(job.command.payload);
  if (committed.hash != run.content_hash) {
    *code = Reason::HashMismatch;
    *reason = "trajectory " + std::to_string(run.trajectory_id) + ": the command's hash " + to_hex(run.content_hash) +
              " differs from the committed upload's " + to_hex(committed.hash);
    return false;
  }
  try {
    job.prepared = std::make_unique<control::PreparedTrajectory>(*committed.trajectory, run.trajectory_id);
  } catch (const std::exception& e) {
    *code = Reason::ValidationFailed;
    *reason = e.what();
    return false;
  }
  job.trajectory = committed.trajectory;
  job.awaiting_upload = 0;
  return true;
}

bool JobFactory::check_goto(const protocol::Command& c, Reason* code, std::string* reason) const {
  const double speed_fraction = c.kind == CommandKind::GotoJoint
                                    ? std::get<protocol::GotoJoint>(c.payload).speed_fraction
                                    : std::get<protocol::GotoCart>(c.payload).speed_fraction;
  if (c.kind == CommandKind::GotoJoint) {
    const auto& p = std::get<protocol::GotoJoint>(c.payload);
    const std::size_t dof = static_cast<std::size_t>(model_.dof());
    if (p.q_rad.size() != dof) {
      *code = Reason::JointCount;
      *reason = std::to_string(p.q_rad.size()) + " joint values for a " + std::to_string(dof) + "-joint arm";
      return false;
    }
    for (std::size_t j = 0; j < dof; ++j) {
      const auto& lim = model_.limits()[j];
      if (!std::isfinite(p.q_rad[j]) || p.q_rad[j] < lim.lower_rad || p.q_rad[j] > lim.upper_rad) {
        *code = Reason::BadArgument;
        *reason = "joint " + std::to_string(j + 1) + printf_text(": %.4f rad outside its limits", p.q_rad[j]) +
                  printf_text(" [%.4f, %.4f]", lim.lower_rad, lim.upper_rad);
        return false;
      }
    }
  } else {
    const auto& p = std::get<protocol::GotoCart>(c.payload);
    const std::string tip = model_.links()[static_cast<std::size_t>(model_.tip_index())].name;
    if (p.frame != tip) {
      *code = Reason::BadArgument;
      *reason = "unknown frame '" + p.frame + "' (GOTO_CART moves the tool tip '" + tip + "')";
      return false;
    }
  }
  if (!(speed_fraction > 0.0 && speed_fraction <= 1.0)) {
    *code = Reason::BadArgument;
    *reason = printf_text("speed_fraction %g out of range (0, 1]", speed_fraction);
    return false;
  }
  if (c.kind == CommandKind::GotoCart && !std::get<protocol::GotoCart>(c.payload).base_T_frame.matrix().allFinite()) {
    *code = Reason::BadArgument;
    *reason = "the target pose is not finite";
    return false;
  }
  return true;
}

bool JobFactory::make_invoke_job(const protocol::InvokeAlgorithm& p, Job& job, Reason* code,
                                 std::string* reason) const {
  if (const auto step = tool_step_from_name(p.name)) {
    if (tool_ == nullptr) {
      *code = Reason::ToolFault;
      *reason = p.name + ": no tool configured";
      return false;
    }
    const std::string why = parse_tool_step(p, *step, tool_->config(), job.tool_step);
    if (!why.empty()) {
      *code = Reason::BadArgument;
      *reason = why;
      return false;
    }
    job.tool_step.command_id = job.command.command_id;
    job.kind = JobKind::ToolStep;
    return true;
  }
  if (p.name == "tare") {
    // Zero the F/T sensor in a stiff hold out of contact (the controller
    // refuses it otherwise). Parameter: samples (1..10000).
    for (const auto& nv : p.params) {
      if (nv.name != "samples") {
        *code = Reason::BadArgument;
        *reason = "tare: unknown parameter '" + nv.name + "' (expected one of: samples)";
        return false;
      }
      if (!(nv.value >= 1.0 && nv.value <= 10000.0) || nv.value != std::floor(nv.value)) {
        *code = Reason::BadArgument;
        *reason = printf_text("tare: samples %g must be an integer in 1..10000", nv.value);
        return false;
      }
      job.tare_samples = static_cast<int>(nv.value);
    }
    job.kind = JobKind::Tare;
    return true;
  }
  const std::string why = parse_algorithm(p, job.algorithm);
  if (!why.empty()) {
    *code = job.algorithm.kind == control::AlgorithmKind::None ? Reason::UnknownAlgorithm : Reason::BadArgument;
    *reason = job.algorithm.kind == control::AlgorithmKind::None
                  ? why + " (expected one of: guarded_move, insert, pull_out, identify_payload, latch, unlatch, loosen, tighten, tare)"
                  : why;
    return false;
  }
  job.kind = JobKind::Algorithm;
  return true;
}

bool JobFactory::plan_goto(Job& job, std::span<const double> q_cmd, Reason* code, std::string* reason) const {
  const std::size_t dof = static_cast<std::size_t>(model_.dof());
  Eigen::VectorXd q0(static_cast<Eigen::Index>(dof));
  for (std::size_t j = 0; j < dof; ++j) q0[static_cast<Eigen::Index>(j)] = q_cmd[j];
  Goal goal;
  PlanOptions options;
  if (const auto* gj = std::get_if<protocol::GotoJoint>(&job.command.payload)) {
    goal.name = "goto_joint";
    goal.kind = SegmentKind::Joint;
    goal.is_pose = false;
    goal.q = Eigen::Map<const Eigen::VectorXd>(gj->q_rad.data(), static_cast<Eigen::Index>(dof));
    options.limit_fraction = gj->speed_fraction;
  } else {
    const auto& gc = std::get<protocol::GotoCart>(job.command.payload);
    goal.name = "goto_cart";
    goal.kind = SegmentKind::Linear;
    goal.is_pose = true;
    goal.base_T_tip = gc.base_T_frame;
    options.limit_fraction = gc.speed_fraction;
    options.tool_speed_m_s = 0.1 * gc.speed_fraction;
  }
  try {
    const Plan plan = plan_motion(model_, q0, {goal}, options);
    job.trajectory = std::make_shared<const Trajectory>(plan.trajectory);
    job.prepared = std::make_unique<control::PreparedTrajectory>(plan.trajectory, 0);
  } catch (const std::exception& e) {
    *code = Reason::Unreachable;
    *reason = e.what();
    return false;
  }
  return true;
}

}  // namespace foresight::daemon

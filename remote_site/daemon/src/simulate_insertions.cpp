#include "foresight/daemon/simulate_insertions.hpp"

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <nlohmann/json.hpp>
#include <ostream>
#include <utility>

#include "foresight/common/error.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/daemon/algorithm_params.hpp"

namespace foresight::daemon {

namespace {

using nlohmann::json;

std::string list_of(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

/// Refuses a key of `j` not in `known`: "<where>unknown key 'k' (expected a, b)".
void require_known_keys(const std::string& path, const std::string& where, const json& j,
                        const std::vector<std::string>& known) {
  for (auto it = j.begin(); it != j.end(); ++it) {
    bool ok = false;
    for (const auto& k : known) ok = ok || it.key() == k;
    if (!ok) throw InputError(path, where + "unknown key '" + it.key() + "' (expected " + list_of(known) + ")");
  }
}

/// The insert's parameters through parse_algorithm (INVOKE_ALGORITHM's names,
/// ranges and messages); timeout_s is the command's own field there.
InsertParams read_params(const std::string& path, const json& j) {
  if (!j.is_object()) throw InputError(path, "params: expected an object of insert parameters (name: number)");
  protocol::InvokeAlgorithm invoke;
  invoke.name = "insert";
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (!it.value().is_number())
      throw InputError(path, "params." + it.key() + ": expected a number");
    const double v = it.value().get<double>();
    if (it.key() == "timeout_s")
      invoke.timeout_s = v;
    else
      invoke.params.push_back({it.key(), v});
  }
  control::AlgorithmParams out;
  const std::string error = parse_algorithm(invoke, out);
  if (!error.empty()) throw InputError(path, "params: " + error);
  return out.insert;
}

/// trials[i].tag_T_tip: 4 rows of 4 numbers, a rigid transform.
Pose read_rigid(const std::string& path, const std::string& where, const json& j) {
  const std::string what = where + ": expected 4 rows of 4 numbers (a rigid transform)";
  if (!j.is_array() || j.size() != 4) throw InputError(path, what);
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r) {
    const json& row = j[static_cast<std::size_t>(r)];
    if (!row.is_array() || row.size() != 4) throw InputError(path, what);
    for (int c = 0; c < 4; ++c) {
      const json& v = row[static_cast<std::size_t>(c)];
      if (!v.is_number()) throw InputError(path, what);
      m(r, c) = v.get<double>();
    }
  }
  if (!m.allFinite()) throw InputError(path, what);
  if (m.row(3) != Eigen::RowVector4d(0.0, 0.0, 0.0, 1.0))
    throw InputError(path, where + ": not a rigid transform (the last row is not [0, 0, 0, 1])");
  const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
  const double off = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (off > kRigidTolerance || R.determinant() <= 0.0) {
    char buf[160];
    std::snprintf(buf, sizeof buf, ": not a rigid transform (|R^T R - I| = %.3g, det R = %.6g; want <= %g and +1)",
                  off, R.determinant(), kRigidTolerance);
    throw InputError(path, where + buf);
  }
  Pose p = Pose::Identity();
  p.linear() = Eigen::Quaterniond(R).normalized().toRotationMatrix();
  p.translation() = m.topRightCorner<3, 1>();
  return p;
}

std::vector<InsertionTrial> read_trials(const std::string& path, const json& doc) {
  if (!doc.contains("trials")) throw InputError(path, "trials: missing (a list of {\"id\", \"tag_T_tip\"})");
  const json& list = doc["trials"];
  if (!list.is_array()) throw InputError(path, "trials: expected a list of {\"id\", \"tag_T_tip\"}");
  if (list.empty()) throw InputError(path, "trials: empty (at least one trial)");
  if (list.size() > kMaxInsertionTrials)
    throw InputError(path, "trials: " + std::to_string(list.size()) + " trials, at most " +
                               std::to_string(kMaxInsertionTrials));
  std::vector<InsertionTrial> trials;
  trials.reserve(list.size());
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string where = "trials[" + std::to_string(i) + "]";
    const json& t = list[i];
    if (!t.is_object()) throw InputError(path, where + ": expected an object {\"id\", \"tag_T_tip\"}");
    require_known_keys(path, where + ": ", t, {"id", "tag_T_tip"});
    InsertionTrial trial;
    if (!t.contains("id") || !t["id"].is_number_integer() ||
        (t["id"].is_number_unsigned() && t["id"].get<std::uint64_t>() > static_cast<std::uint64_t>(INT64_MAX)))
      throw InputError(path, where + ".id: expected an integer");
    trial.id = t["id"].get<std::int64_t>();
    if (!t.contains("tag_T_tip")) throw InputError(path, where + ".tag_T_tip: missing");
    trial.tag_T_tip = read_rigid(path, where + ".tag_T_tip", t["tag_T_tip"]);
    trials.push_back(trial);
  }
  return trials;
}

}  // namespace

InsertionBatch read_insertion_batch(const std::string& path, const sim_insertion::WorldFiles& defaults) {
  const std::string text = read_text_file(path, "cannot open the insertion batch file");
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::parse_error& e) {
    throw InputError(path, std::string("malformed JSON: ") + e.what());
  }
  if (!doc.is_object()) throw InputError(path, "expected a JSON object {\"trials\": [...]}");
  require_known_keys(path, "", doc, {"object", "tag", "params", "trials"});

  InsertionBatch batch;
  batch.files = defaults;
  if (doc.contains("object")) {
    if (!doc["object"].is_string()) throw InputError(path, "object: expected the object model's file name");
    batch.files.object_yaml = doc["object"].get<std::string>();
  }
  if (doc.contains("tag")) {
    if (!doc["tag"].is_string()) throw InputError(path, "tag: expected a tag name");
    batch.tag = doc["tag"].get<std::string>();
  }
  const ObjectModel model = ObjectModel::from_file(batch.files.object_yaml);  // InputError naming that file
  const auto tag = model.tags.find(batch.tag);
  if (tag == model.tags.end()) {
    std::vector<std::string> names;
    for (const auto& [name, pose] : model.tags) names.push_back(name);
    throw InputError(path, "tag: '" + batch.tag + "' is not a tag of " + batch.files.object_yaml + " (tags: " +
                               list_of(names) + ")");
  }
  batch.oru_T_tag = tag->second;
  batch.params = read_params(path, doc.contains("params") ? doc["params"] : json::object());
  batch.trials = read_trials(path, doc);
  return batch;
}

InsertionReport simulate_insertions(const InsertionBatch& batch) {
  const auto t0 = std::chrono::steady_clock::now();
  sim_insertion::World world(batch.files);
  sim_insertion::InsertSpec spec;
  spec.params = batch.params;
  const Pose base_T_tag = world.base_T_oru * batch.oru_T_tag;
  InsertionReport report;
  report.results.reserve(batch.trials.size());
  std::size_t successes = 0;
  for (const InsertionTrial& trial : batch.trials) {
    InsertionResult r;
    r.id = trial.id;
    const Pose base_T_start = base_T_tag * trial.tag_T_tip;
    const std::optional<Eigen::VectorXd> q0 = world.start_joints(base_T_start);
    // The start is where the approach ends: a stiff position-controlled
    // motion that ends inside the ORU pressed into it on the way. The
    // contact at the start, at rest, above the insert's force limit: the
    // approach would have been stopped by the force check before the insert.
    const sim::ContactResult start_contact = world.plant->tool_contact_model().compute(base_T_start, world.base_T_oru);
    if (!q0) {
      r.reason = "unreachable_start";
      r.text = "no joints put the tool tip at the start pose (IK)";
    } else if (start_contact.force_base_n.norm() > spec.params.max_force_n) {
      r.reason = "approach_collision";
      r.peak_force_n = start_contact.force_base_n.norm();
      r.text = "the approach ends " + std::to_string(start_contact.max_penetration_m * 1e3) +
               " mm inside the ORU: its contact force " + std::to_string(r.peak_force_n) + " N is above max_force_n";
    } else {
      const sim_insertion::Outcome o = sim_insertion::run_insertion(world, *q0, spec);
      r.success = o.success();
      r.completed = o.completed;
      r.in_hole = o.in_hole;
      r.reason = protocol::to_string(o.code);
      r.text = o.text.data();
      r.peak_force_n = o.peak_force_n;
      r.sim_s = o.sim_s;
      r.searched = o.searched;
      r.face_contact = o.touched_face;
    }
    successes += r.success ? 1 : 0;
    report.results.push_back(std::move(r));
  }
  report.success_rate = static_cast<double>(successes) / static_cast<double>(batch.trials.size());
  report.compute_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return report;
}

std::string insertion_report_json(const InsertionReport& report) {
  json results = json::array();
  for (const InsertionResult& r : report.results)
    results.push_back({{"id", r.id},
                       {"success", r.success},
                       {"completed", r.completed},
                       {"in_hole", r.in_hole},
                       {"reason", r.reason},
                       {"peak_force_n", r.peak_force_n},
                       {"sim_s", r.sim_s},
                       {"searched", r.searched},
                       {"face_contact", r.face_contact}});
  json j;
  j["trials"] = report.results.size();
  j["results"] = std::move(results);
  j["success_rate"] = report.success_rate;
  j["compute_s"] = report.compute_s;
  return json_text(j);
}

std::string insertion_report_text(const InsertionReport& report) {
  std::string s = "      id  ok  reason             peak N   sim s  search  face  text\n";
  char line[256];
  for (const InsertionResult& r : report.results) {
    std::snprintf(line, sizeof line, "%8lld  %-3s %-17s %7.1f %7.2f  %-6s  %-4s  %s\n",
                  static_cast<long long>(r.id), r.success ? "yes" : "no", r.reason.c_str(), r.peak_force_n, r.sim_s,
                  r.searched ? "yes" : "no", r.face_contact ? "yes" : "no", r.text.c_str());
    s += line;
  }
  std::snprintf(line, sizeof line, "%zu trials, success rate %.3f, compute %.2f s\n", report.results.size(),
                report.success_rate, report.compute_s);
  return s + line;
}

int run_simulate_insertions_command(const std::string& batch_path, const std::string& config_dir, bool json_out,
                                    std::ostream& out, std::ostream& err) {
  try {
    const InsertionBatch batch = read_insertion_batch(batch_path, sim_insertion::default_files(config_dir));
    const InsertionReport report = simulate_insertions(batch);
    out << (json_out ? insertion_report_json(report) + "\n" : insertion_report_text(report));
    return kExitOk;
  } catch (const InputError& e) {
    err << "foresight-remote: error: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    err << "foresight-remote: error: " << e.what() << "\n";
    return kExitFailure;
  }
}

}  // namespace foresight::daemon

#include "foresight/sim/sim_node.hpp"

#include "foresight/hw/can_bus.hpp"

namespace foresight::sim {

using namespace hw::canopen;
using hw::get_u16;
using hw::get_u32;
using hw::put_u16;
using hw::put_u32;

SimNode::SimNode(std::uint8_t node_id, std::uint32_t device_type, std::string device_name)
    : node_id_(node_id), device_type_(device_type), device_name_(std::move(device_name)) {}

SimNode::~SimNode() = default;

NmtState SimNode::nmt_state() const {
  std::lock_guard lock(mu_);
  return nmt_;
}
void SimNode::silence_heartbeat(bool silent) {
  std::lock_guard lock(mu_);
  silent_hb_ = silent;
}
void SimNode::stop_answering(bool silent) {
  std::lock_guard lock(mu_);
  silent_ = silent;
}
void SimNode::inject_sdo_abort(std::uint16_t index, std::uint8_t sub, std::uint32_t code) {
  std::lock_guard lock(mu_);
  pending_aborts_[key(index, sub)] = code;
}
void SimNode::drop_sdo_responses(std::uint16_t index, std::uint8_t sub, int count) {
  std::lock_guard lock(mu_);
  if (count > 0) dropped_responses_[key(index, sub)] = count;
  else dropped_responses_.erase(key(index, sub));
}
void SimNode::inject_bad_toggle(bool on) {
  std::lock_guard lock(mu_);
  bad_toggle_ = on;
}
void SimNode::send_emcy(std::uint16_t code, std::uint8_t error_register) {
  std::lock_guard lock(mu_);
  pending_emcy_ = true;
  pending_emcy_code_ = code;
  pending_emcy_reg_ = error_register;
}
void SimNode::inject_reboot() {
  std::lock_guard lock(mu_);
  pending_reboot_ = true;
}
std::uint64_t SimNode::frames_handled() const {
  std::lock_guard lock(mu_);
  return frames_;
}

void SimNode::define(std::uint16_t index, std::uint8_t sub, std::uint8_t size, bool writable, std::uint32_t value) {
  Entry e;
  e.size = size;
  e.writable = writable;
  e.value = value;
  od_[key(index, sub)] = e;
}
std::uint32_t SimNode::get(std::uint16_t index, std::uint8_t sub) const {
  auto it = od_.find(key(index, sub));
  return it == od_.end() ? 0 : it->second.value;
}
void SimNode::set(std::uint16_t index, std::uint8_t sub, std::uint32_t value) {
  auto it = od_.find(key(index, sub));
  if (it != od_.end()) it->second.value = value;
}

void SimNode::reset_communication() {
  define(od::kDeviceType, 0, 4, false, device_type_);
  define(od::kErrorRegister, 0, 1, false, 0);
  Entry name;
  name.size = 0;
  name.text = device_name_;
  od_[key(od::kDeviceName, 0)] = name;
  define(od::kProducerHeartbeat, 0, 2, true, 0);
  seg_active_ = false;
  hb_armed_ = false;
}

void SimNode::boot(FrameSink& out) {
  od_.clear();
  reset_communication();
  reset_application();
  nmt_ = NmtState::PreOperational;
  out.send(hw::make_frame(kHeartbeatBase + node_id_, {0x00}));  // boot-up
}

void SimNode::power_on(FrameSink& out) {
  std::lock_guard lock(mu_);
  if (!silent_) boot(out);
}

void SimNode::emit_emcy(std::uint16_t code, std::uint8_t error_register, FrameSink& out) {
  set(od::kErrorRegister, 0, error_register);
  can_frame f = hw::make_frame(kEmcyBase + node_id_, {0, 0, 0, 0, 0, 0, 0, 0});
  put_u16(f.data, code);
  f.data[2] = error_register;
  out.send(f);
}

void SimNode::on_frame(const can_frame&, FrameSink&) {}
void SimNode::on_tick(Clock::time_point, FrameSink&) {}
std::uint32_t SimNode::check_sdo_write(std::uint16_t, std::uint8_t, std::uint32_t) { return 0; }
void SimNode::on_sdo_written(std::uint16_t, std::uint8_t) {}

void SimNode::handle(const can_frame& f, Clock::time_point now, FrameSink& out) {
  std::lock_guard lock(mu_);
  if (silent_) return;
  now_ = now;
  if (f.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) return;
  const std::uint32_t id = f.can_id & CAN_SFF_MASK;
  if (id == kNmt) {
    if (f.can_dlc != 2 || (f.data[1] != 0 && f.data[1] != node_id_)) return;
    ++frames_;
    switch (static_cast<NmtCommand>(f.data[0])) {
      case NmtCommand::Start: nmt_ = NmtState::Operational; break;
      case NmtCommand::Stop: nmt_ = NmtState::Stopped; break;
      case NmtCommand::EnterPreOperational: nmt_ = NmtState::PreOperational; break;
      case NmtCommand::ResetNode: boot(out); break;
      case NmtCommand::ResetCommunication: {
        const auto app = od_;
        reset_communication();
        for (const auto& [k, e] : app)
          if ((k >> 8) >= 0x2000) od_[k] = e;  // application part survives
        nmt_ = NmtState::PreOperational;
        out.send(hw::make_frame(kHeartbeatBase + node_id_, {0x00}));
        break;
      }
    }
    return;
  }
  if (id == kSync) {
    if (nmt_ == NmtState::Operational) {
      ++frames_;
      on_sync(now, out);
    }
    return;
  }
  if (id == kSdoRxBase + node_id_) {
    ++frames_;
    if (nmt_ != NmtState::Stopped) sdo(f, out);
    return;
  }
  on_frame(f, out);
}

void SimNode::tick(Clock::time_point now, FrameSink& out) {
  std::lock_guard lock(mu_);
  if (silent_) return;
  now_ = now;
  if (pending_reboot_) {
    pending_reboot_ = false;
    boot(out);
  }
  if (pending_emcy_) {
    pending_emcy_ = false;
    emit_emcy(pending_emcy_code_, pending_emcy_reg_, out);
  }
  on_tick(now, out);
  const std::uint32_t period_ms = get(od::kProducerHeartbeat, 0);
  if (period_ms == 0) {
    hb_armed_ = false;
    return;
  }
  const auto period = std::chrono::milliseconds(period_ms);
  if (!hb_armed_) {
    hb_armed_ = true;
    next_hb_ = now + period;
    return;
  }
  if (now >= next_hb_) {
    next_hb_ += period;
    if (next_hb_ < now) next_hb_ = now + period;  // fell far behind: do not burst
    if (!silent_hb_) out.send(hw::make_frame(kHeartbeatBase + node_id_, {static_cast<std::uint8_t>(nmt_)}));
  }
}

void SimNode::sdo_abort(std::uint16_t index, std::uint8_t sub, std::uint32_t code, FrameSink& out) {
  can_frame r = hw::make_frame(kSdoTxBase + node_id_, {0x80, 0, 0, 0, 0, 0, 0, 0});
  put_u16(r.data + 1, index);
  r.data[3] = sub;
  put_u32(r.data + 4, code);
  seg_active_ = false;
  out.send(r);
}

void SimNode::sdo(const can_frame& f, FrameSink& out) {
  if (f.can_dlc != 8) return;  // CiA 301: SDO frames are 8 bytes; ignore others
  const std::uint8_t cmd = f.data[0];
  const std::uint8_t cs = cmd >> 5;
  const std::uint16_t index = get_u16(f.data + 1);
  const std::uint8_t sub = f.data[3];
  if (cs == sdo::kCsAbort) {
    seg_active_ = false;
    return;
  }
  if (cs != sdo::kCcsUploadSegment && !dropping_ && !dropped_responses_.empty()) {
    if (auto it = dropped_responses_.find(key(index, sub)); it != dropped_responses_.end()) {
      if (--it->second <= 0) dropped_responses_.erase(it);
      struct Lost final : FrameSink {
        void send(const can_frame&) override {}
      } lost;
      dropping_ = true;
      sdo(f, lost);  // served; the response never reaches the master
      dropping_ = false;
      return;
    }
  }
  if (cs == sdo::kCcsUploadSegment) {
    if (!seg_active_) return sdo_abort(index, sub, static_cast<std::uint32_t>(SdoAbort::BadCommand), out);
    const std::uint8_t t = (cmd >> 4) & 1;
    if (t != seg_toggle_) return sdo_abort(seg_index_, seg_sub_, static_cast<std::uint32_t>(SdoAbort::ToggleBit), out);
    const std::size_t n = std::min<std::size_t>(7, seg_data_.size() - seg_pos_);
    const bool last = seg_pos_ + n >= seg_data_.size();
    std::uint8_t sent_t = t;
    if (bad_toggle_ && seg_count_ == 1) sent_t ^= 1;
    can_frame r = hw::make_frame(kSdoTxBase + node_id_, {0, 0, 0, 0, 0, 0, 0, 0});
    r.data[0] = static_cast<std::uint8_t>((sent_t << 4) | ((7 - n) << 1) | (last ? 1 : 0));
    for (std::size_t i = 0; i < n; ++i) r.data[1 + i] = static_cast<std::uint8_t>(seg_data_[seg_pos_ + i]);
    seg_pos_ += n;
    seg_toggle_ ^= 1;
    ++seg_count_;
    if (last) seg_active_ = false;
    out.send(r);
    return;
  }
  if (cs != sdo::kCcsDownloadInitiate && cs != sdo::kCcsUploadInitiate)
    return sdo_abort(index, sub, static_cast<std::uint32_t>(SdoAbort::BadCommand), out);

  if (auto pa = pending_aborts_.find(key(index, sub)); pa != pending_aborts_.end()) {
    const std::uint32_t code = pa->second;
    pending_aborts_.erase(pa);
    return sdo_abort(index, sub, code, out);
  }
  auto it = od_.find(key(index, sub));
  if (it == od_.end()) {
    const bool index_exists = od_.lower_bound(key(index, 0)) != od_.end() &&
                              (od_.lower_bound(key(index, 0))->first >> 8) == index;
    return sdo_abort(index, sub,
                     static_cast<std::uint32_t>(index_exists ? SdoAbort::NoSubIndex : SdoAbort::NoObject), out);
  }
  Entry& e = it->second;
  can_frame r = hw::make_frame(kSdoTxBase + node_id_, {0, 0, 0, 0, 0, 0, 0, 0});
  put_u16(r.data + 1, index);
  r.data[3] = sub;

  if (cs == sdo::kCcsDownloadInitiate) {
    if (!(cmd & 0x02)) return sdo_abort(index, sub, static_cast<std::uint32_t>(SdoAbort::UnsupportedAccess), out);
    if (!e.writable || e.size == 0) return sdo_abort(index, sub, static_cast<std::uint32_t>(SdoAbort::ReadOnly), out);
    const int size = (cmd & 0x01) ? 4 - ((cmd >> 2) & 0x03) : e.size;
    if (size != e.size)
      return sdo_abort(index, sub,
                       static_cast<std::uint32_t>(size > e.size ? SdoAbort::LengthTooHigh : SdoAbort::LengthTooLow), out);
    std::uint32_t v = 0;
    for (int i = 0; i < size; ++i) v |= static_cast<std::uint32_t>(f.data[4 + i]) << (8 * i);
    if (const std::uint32_t abort = check_sdo_write(index, sub, v)) return sdo_abort(index, sub, abort, out);
    e.value = v;
    on_sdo_written(index, sub);
    r.data[0] = 0x60;
    out.send(r);
    return;
  }
  // upload
  if (e.size == 0) {
    if (e.text.size() <= 4) {
      r.data[0] = static_cast<std::uint8_t>(0x43 | ((4 - e.text.size()) << 2));
      for (std::size_t i = 0; i < e.text.size(); ++i) r.data[4 + i] = static_cast<std::uint8_t>(e.text[i]);
    } else {
      r.data[0] = 0x41;
      put_u32(r.data + 4, static_cast<std::uint32_t>(e.text.size()));
      seg_active_ = true;
      seg_data_ = e.text;
      seg_pos_ = 0;
      seg_toggle_ = 0;
      seg_count_ = 0;
      seg_index_ = index;
      seg_sub_ = sub;
    }
    out.send(r);
    return;
  }
  r.data[0] = static_cast<std::uint8_t>(0x43 | ((4 - e.size) << 2));
  put_u32(r.data + 4, e.value);
  out.send(r);
}

}  // namespace foresight::sim

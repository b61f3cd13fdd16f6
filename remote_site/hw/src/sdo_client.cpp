#include "foresight/hw/sdo_client.hpp"

#include <poll.h>

#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>

#include "foresight/hw/canopen.hpp"

namespace foresight::hw {

using namespace canopen;
using Clock = std::chrono::steady_clock;

std::string hex_text(std::uint32_t v, int digits) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%0*" PRIX32, digits, v);
  return buf;
}

std::string od_name(std::uint16_t index, std::uint8_t sub) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%04X:%02X", index, sub);
  return buf;
}

void write_setup_frame(CanBus& b, const std::string& bus_name, const can_frame& f) {
  const auto deadline = Clock::now() + std::chrono::milliseconds(100);
  for (;;) {
    const CanIo io = b.write(f);
    if (io == CanIo::Ok) return;
    if (io != CanIo::WouldBlock || Clock::now() > deadline)
      throw HwError("bus " + bus_name + ": cannot send COB-ID " + hex_text(f.can_id, 3) + ": " + to_string(io));
    pollfd p{b.fd(), POLLOUT, 0};
    ::poll(&p, 1, 5);
  }
}

SdoClient::SdoClient(CanBus& bus, std::string bus_name, double timeout_s, FrameHandler other_frames, NodeLabel label)
    : bus_(bus), bus_name_(std::move(bus_name)), timeout_s_(timeout_s), other_(std::move(other_frames)),
      label_(std::move(label)) {}

can_frame SdoClient::exchange(std::uint8_t node, const can_frame& request, const char* what, std::uint16_t index,
                              std::uint8_t sub, bool retry) {
  const std::string label = std::string("SDO ") + what + " " + od_name(index, sub) + " of " + label_(node);
  const int timeout_ms = static_cast<int>(std::lround(timeout_s_ * 1000));
  // One lost frame (the request or the response) must not fail a whole
  // bring-up: a timed-out transfer is aborted and sent once more (expedited
  // and initiate requests only: a segment cannot be repeated after its abort).
  const int attempts = retry ? 2 : 1;
  for (int attempt = 1;; ++attempt) {
    try {
      const can_frame r = exchange_once(node, request, label, index, sub);
      if (attempt > 1)
        notices_.push_back(label + ": no response within " + std::to_string(timeout_ms) +
                           " ms; the retry was answered");
      return r;
    } catch (const SdoError& e) {
      if (e.kind() != SdoError::Kind::Timeout || attempt >= attempts) {
        if (e.kind() == SdoError::Kind::Timeout && attempts > 1)
          throw SdoError(SdoError::Kind::Timeout, e.abort_code(),
                         label + ": timed out after " + std::to_string(timeout_ms) +
                             " ms (no response), also on the retry");
        throw;
      }
    }
  }
}

can_frame SdoClient::exchange_once(std::uint8_t node, const can_frame& request, const std::string& label,
                                   std::uint16_t index, std::uint8_t sub) {
  write_setup_frame(bus_, bus_name_, request);
  const auto timeout = std::chrono::duration<double>(timeout_s_);
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(timeout);
  for (;;) {
    can_frame f{};
    const CanIo io = inbox_ == nullptr ? bus_.read(f) : (inbox_->try_pop(f) ? CanIo::Ok : CanIo::WouldBlock);
    const auto now = Clock::now();
    if (io == CanIo::Ok) {
      if ((f.can_id & CAN_SFF_MASK) == kSdoTxBase + node && !(f.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG))) {
        if (f.can_dlc != 8)
          throw SdoError(SdoError::Kind::Protocol, static_cast<std::uint32_t>(SdoAbort::BadCommand),
                         label + ": malformed response (DLC " + std::to_string(f.can_dlc) + ", expected 8)");
        return f;
      }
      if (other_) other_(f);
      continue;
    }
    if (io == CanIo::Closed || io == CanIo::SysError || io == CanIo::BusOff || io == CanIo::NetDown)
      throw HwError(label + ": bus " + bus_name_ + ": " + to_string(io));
    if (now >= deadline) {
      can_frame abort = make_frame(kSdoRxBase + node, {0x80, 0, 0, 0, 0, 0, 0, 0});
      put_u16(abort.data + 1, index);
      abort.data[3] = sub;
      put_u32(abort.data + 4, static_cast<std::uint32_t>(SdoAbort::Timeout));
      (void)bus_.write(abort);
      throw SdoError(SdoError::Kind::Timeout, static_cast<std::uint32_t>(SdoAbort::Timeout),
                     label + ": timed out after " + std::to_string(static_cast<int>(std::lround(timeout_s_ * 1000))) +
                         " ms (no response)");
    }
    if (io == CanIo::ErrorFrame || io == CanIo::Malformed) continue;
    if (inbox_ != nullptr) {  // the cycle hands the answers over: look again in 1 ms
      ::poll(nullptr, 0, 1);
      continue;
    }
    pollfd p{bus_.fd(), POLLIN, 0};
    const auto left_ms = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - now).count() + 1;
    ::poll(&p, 1, static_cast<int>(left_ms));
  }
}

void SdoClient::throw_response_error(const can_frame& r, const std::string& label, std::uint16_t index,
                                     std::uint8_t sub) const {
  const std::uint8_t cs = r.data[0] >> 5;
  if (cs == sdo::kCsAbort) {
    const std::uint32_t code = get_u32(r.data + 4);
    throw SdoError(SdoError::Kind::Abort, code,
                   label + ": aborted by the node: " + hex_text(code, 8) + " " + sdo_abort_text(code));
  }
  const std::uint16_t ri = get_u16(r.data + 1);
  if (ri != index || r.data[3] != sub)
    throw SdoError(SdoError::Kind::Protocol, static_cast<std::uint32_t>(SdoAbort::General),
                   label + ": response is for " + od_name(ri, r.data[3]));
  throw SdoError(SdoError::Kind::Protocol, static_cast<std::uint32_t>(SdoAbort::BadCommand),
                 label + ": unexpected response command byte " + hex_text(r.data[0], 2));
}

std::uint32_t SdoClient::read(std::uint8_t node, std::uint16_t index, std::uint8_t sub) {
  can_frame req = make_frame(kSdoRxBase + node, {0x40, 0, 0, 0, 0, 0, 0, 0});
  put_u16(req.data + 1, index);
  req.data[3] = sub;
  const can_frame r = exchange(node, req, "read", index, sub, true);
  const std::string label = "SDO read " + od_name(index, sub) + " of " + label_(node);
  const std::uint8_t cmd = r.data[0];
  const bool ok_echo = get_u16(r.data + 1) == index && r.data[3] == sub;
  if ((cmd >> 5) == sdo::kScsUploadInitiate && ok_echo) {
    if (!(cmd & 0x02))
      throw SdoError(SdoError::Kind::Protocol, static_cast<std::uint32_t>(SdoAbort::LengthTooHigh),
                     label + ": node answered with a segmented transfer for a numeric object");
    const int size = (cmd & 0x01) ? 4 - ((cmd >> 2) & 0x03) : 4;
    std::uint32_t v = 0;
    for (int i = 0; i < size; ++i) v |= static_cast<std::uint32_t>(r.data[4 + i]) << (8 * i);
    return v;
  }
  throw_response_error(r, label, index, sub);
}

void SdoClient::write(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t value, int size) {
  if (size < 1 || size > 4) throw HwError("sdo_write: size must be 1..4 bytes");
  can_frame req = make_frame(kSdoRxBase + node, {sdo::expedited_download(size), 0, 0, 0, 0, 0, 0, 0});
  put_u16(req.data + 1, index);
  req.data[3] = sub;
  for (int i = 0; i < size; ++i) req.data[4 + i] = static_cast<std::uint8_t>(value >> (8 * i));
  const can_frame r = exchange(node, req, "write", index, sub, true);
  const bool ok_echo = get_u16(r.data + 1) == index && r.data[3] == sub;
  if (r.data[0] == 0x60 && ok_echo) return;
  throw_response_error(r, "SDO write " + od_name(index, sub) + " of " + label_(node), index, sub);
}

std::string SdoClient::read_string(std::uint8_t node, std::uint16_t index, std::uint8_t sub) {
  const std::string label = "SDO read " + od_name(index, sub) + " of " + label_(node);
  can_frame req = make_frame(kSdoRxBase + node, {0x40, 0, 0, 0, 0, 0, 0, 0});
  put_u16(req.data + 1, index);
  req.data[3] = sub;
  const can_frame r = exchange(node, req, "read", index, sub, true);
  const std::uint8_t cmd = r.data[0];
  if ((cmd >> 5) != sdo::kScsUploadInitiate || get_u16(r.data + 1) != index || r.data[3] != sub)
    throw_response_error(r, label, index, sub);
  if (cmd & 0x02) {  // expedited
    const int size = (cmd & 0x01) ? 4 - ((cmd >> 2) & 0x03) : 4;
    std::string s(reinterpret_cast<const char*>(r.data + 4), static_cast<std::size_t>(size));
    return s.substr(0, s.find('\0'));
  }
  constexpr std::uint32_t kMaxString = 1024;
  const bool size_known = cmd & 0x01;
  const std::uint32_t size = size_known ? get_u32(r.data + 4) : 0;
  auto abort_with = [&](SdoAbort code, const std::string& why) {
    can_frame a = make_frame(kSdoRxBase + node, {0x80, 0, 0, 0, 0, 0, 0, 0});
    put_u16(a.data + 1, index);
    a.data[3] = sub;
    put_u32(a.data + 4, static_cast<std::uint32_t>(code));
    (void)bus_.write(a);
    throw SdoError(SdoError::Kind::Protocol, static_cast<std::uint32_t>(code),
                   label + ": " + why + " (sent abort " + hex_text(static_cast<std::uint32_t>(code), 8) + " " +
                       sdo_abort_text(static_cast<std::uint32_t>(code)) + ")");
  };
  if (size > kMaxString) abort_with(SdoAbort::OutOfMemory, "announced size " + std::to_string(size) + " is too long");
  std::string out;
  std::uint8_t toggle = 0;
  for (std::uint32_t segment = 0; segment <= kMaxString / 7 + 1; ++segment) {
    const can_frame seg_req =
        make_frame(kSdoRxBase + node, {static_cast<std::uint8_t>(0x60 | (toggle << 4)), 0, 0, 0, 0, 0, 0, 0});
    const can_frame s = exchange(node, seg_req, "read (segment)", index, sub, false);
    const std::uint8_t c = s.data[0];
    if ((c >> 5) == sdo::kCsAbort) throw_response_error(s, label, index, sub);
    if ((c >> 5) != sdo::kScsUploadSegment)
      abort_with(SdoAbort::BadCommand, "unexpected segment command byte " + hex_text(c, 2));
    if (((c >> 4) & 1) != toggle)
      abort_with(SdoAbort::ToggleBit, "segment " + std::to_string(out.size() / 7) + " has toggle bit " +
                                          std::to_string((c >> 4) & 1) + ", expected " + std::to_string(toggle));
    const int n = 7 - ((c >> 1) & 0x07);
    out.append(reinterpret_cast<const char*>(s.data + 1), static_cast<std::size_t>(n));
    if (out.size() > kMaxString) abort_with(SdoAbort::OutOfMemory, "string longer than 1024 bytes");
    if (c & 0x01) {
      if (size_known && out.size() != size)
        throw SdoError(SdoError::Kind::Protocol, static_cast<std::uint32_t>(SdoAbort::LengthMismatch),
                       label + ": received " + std::to_string(out.size()) + " bytes, announced " +
                           std::to_string(size));
      return out.substr(0, out.find('\0'));
    }
    toggle ^= 1;
  }
  abort_with(SdoAbort::OutOfMemory, "string longer than 1024 bytes");
  return {};  // not reached: abort_with throws
}

}  // namespace foresight::hw

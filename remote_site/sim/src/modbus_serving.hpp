#pragma once
// What the simulated Modbus devices (LstServer, VideoSwitchServer) share: the
// TCP serving step (accept the newest client, receive one request, drop a
// dead client, flush a garbled stream) and the decoding of which holding
// registers a request would write, so each device range-checks every write
// function (FC 6, 16, 22 mask write, 23 write-and-read) in one place.
// Internal to foresight_sim.

#include <modbus/modbus.h>

#include <cstdint>
#include <functional>

namespace foresight::sim::modbus_serving {

/// One turn of a TCP server loop: waits up to poll_ms for a new client or a
/// request; the newest client wins (one at a time); a request is handed to
/// `serve(rc)` (rc = its length in `query`); a client that hung up or reset is
/// closed; a garbled request is flushed.
void serve_tcp_once(modbus_t* ctx, int listen_fd, int& client_fd, std::uint8_t* query, int poll_ms,
                    const std::function<void(int rc)>& serve);

/// Calls `write(address, value)` for every holding register the request in
/// `query` (length rc) would write, with the value it would have (FC 22: from
/// the register's present value in `map`), until `write` returns false;
/// returns false then (the device refuses: exception 03, nothing changes),
/// true when every write is acceptable or the request writes no register.
bool register_writes_ok(modbus_t* ctx, const std::uint8_t* query, int rc, const modbus_mapping_t* map,
                        const std::function<bool(int address, std::uint16_t value)>& write);

}  // namespace foresight::sim::modbus_serving

#include "modbus_serving.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>

namespace foresight::sim::modbus_serving {

namespace {
std::uint16_t word_at(const std::uint8_t* p) { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }
}  // namespace

void serve_tcp_once(modbus_t* ctx, int listen_fd, int& client_fd, std::uint8_t* query, int poll_ms,
                    const std::function<void(int rc)>& serve) {
  pollfd fds[2] = {{listen_fd, POLLIN, 0}, {client_fd, POLLIN, 0}};
  const int n = poll(fds, client_fd >= 0 ? 2 : 1, poll_ms);
  if (n <= 0) return;
  if (fds[0].revents & POLLIN) {
    const int fd = accept4(listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd >= 0) {
      if (client_fd >= 0) close(client_fd);  // one client at a time: the newest wins
      client_fd = fd;
      modbus_set_socket(ctx, client_fd);
    }
    return;
  }
  if (client_fd < 0 || !(fds[1].revents & (POLLIN | POLLHUP | POLLERR))) return;
  const int rc = modbus_receive(ctx, query);
  if (rc > 0) {
    serve(rc);
  } else if (rc == -1 && errno != ETIMEDOUT) {
    if (errno == ECONNRESET || errno == EBADF || errno == EPIPE || errno == ENOTCONN || errno == EIO ||
        (fds[1].revents & (POLLHUP | POLLERR))) {
      close(client_fd);
      client_fd = -1;
      modbus_set_socket(ctx, -1);
    } else {
      modbus_flush(ctx);  // garbled request: drop what is buffered
    }
  }
}

bool register_writes_ok(modbus_t* ctx, const std::uint8_t* q, int rc, const modbus_mapping_t* map,
                        const std::function<bool(int address, std::uint16_t value)>& write) {
  const int h = modbus_get_header_length(ctx);
  if (rc <= h) return true;
  const int fc = q[h];
  if (fc == MODBUS_FC_WRITE_SINGLE_REGISTER && rc >= h + 5) return write(word_at(q + h + 1), word_at(q + h + 3));
  if (fc == MODBUS_FC_WRITE_MULTIPLE_REGISTERS && rc >= h + 6) {
    const int address = word_at(q + h + 1);
    const int count = word_at(q + h + 3);
    for (int i = 0; i < count && rc >= h + 6 + 2 * (i + 1); ++i)
      if (!write(address + i, word_at(q + h + 6 + 2 * i))) return false;
    return true;
  }
  if (fc == MODBUS_FC_MASK_WRITE_REGISTER && rc >= h + 7) {
    // FC 22: result = (current AND and_mask) OR (or_mask AND NOT and_mask).
    const int address = word_at(q + h + 1);
    const std::uint16_t and_mask = word_at(q + h + 3);
    const std::uint16_t or_mask = word_at(q + h + 5);
    if (address < 0 || address >= map->nb_registers) return true;  // libmodbus answers exception 02
    const std::uint16_t current = map->tab_registers[address];
    return write(address, static_cast<std::uint16_t>((current & and_mask) | (or_mask & ~and_mask)));
  }
  if (fc == MODBUS_FC_WRITE_AND_READ_REGISTERS && rc >= h + 10) {
    // FC 23: read address, read count, write address, write count, byte count, values.
    const int address = word_at(q + h + 5);
    const int count = word_at(q + h + 7);
    for (int i = 0; i < count && rc >= h + 10 + 2 * (i + 1); ++i)
      if (!write(address + i, word_at(q + h + 10 + 2 * i))) return false;
    return true;
  }
  return true;
}

}  // namespace foresight::sim::modbus_serving

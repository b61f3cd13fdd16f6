#pragma once
// Writing an output file so that it is either the complete new content or the
// old file untouched, never a truncated mix (a full disk, a crash, a signal
// mid-write): write a temporary file in the same folder, fsync it, rename it
// over the target, fsync the folder. Every CLI output file goes through here.
// Set-up code (blocking I/O, allocates, throws).

#include <string>
#include <string_view>

namespace foresight {

/// Replaces `path` with `content` atomically. Throws InputError as
/// check_output_path, and ComputationError "<path>: cannot write (<reason>);
/// the old file is unchanged" when the write fails (a full disk: the old
/// file, if any, is left as it was and the temporary file is removed).
void write_file_atomic(const std::string& path, std::string_view content);

/// Throws InputError "<path>: is a directory" when `path` names a folder, and
/// "<path>: folder '<dir>' does not exist" when its folder is missing: check
/// an --out option before any work is done.
void check_output_path(const std::string& path);

}  // namespace foresight

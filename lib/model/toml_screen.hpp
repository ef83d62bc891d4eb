// Screening of scene-file text before toml++ parses it (private to lib/model).
//
// toml++ 3.3 (Debian's libtomlplusplus-dev) classifies a non-ASCII code point as whitespace with
// a generated table that reaches __builtin_unreachable() for many ordinary code points (U+00A1
// to U+0499, which holds Latin-1 letters, Greek and Cyrillic, U+2C6E to U+3067 and U+FC06 to
// U+FEFE): undefined behaviour, found by the robustness run of tests/model/scene_file_test.cpp
// under UndefinedBehaviorSanitizer (upstream: toml++ issues 190 and 295, fixed after 3.3). The
// parser asks that question only where whitespace may stand: outside strings and comments,
// right after a backslash in a basic string, and after a line-ending backslash in a multi-line
// basic string. None of those positions may hold a non-ASCII character in valid TOML, so
// rejecting them here loses no valid file and keeps every non-ASCII character toml++ sees inside
// string or comment text, where it never classifies whitespace.
#pragma once

#include <string>

namespace moreau::detail {

/// Throws std::invalid_argument "source:line:column: ..." if `text` is not valid UTF-8, or holds
/// a non-ASCII character outside strings and comments, or right after a backslash (an escape or
/// a line-ending backslash and the whitespace after it) in a basic string. Columns count code
/// points from 1, as toml++'s messages do.
void ScreenTomlText(const std::string& text, const std::string& source);

}  // namespace moreau::detail

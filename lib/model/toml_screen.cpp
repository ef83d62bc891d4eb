// Screening of scene-file text before toml++ parses it: lib/model/toml_screen.hpp says why.
#include "toml_screen.hpp"

#include <cstdint>
#include <cstdio>

#include "moreau/core/error.hpp"

namespace moreau::detail {
namespace {

// Where the lexer stands: the TOML string and comment forms (TOML 1.0, "String" and "Comment").
enum class Context { kCode, kComment, kBasic, kLiteral, kMultiBasic, kMultiLiteral };

// Decodes the UTF-8 sequence at text[i] (RFC 3629: no overlong forms, no surrogates, at most
// U+10FFFF). Returns its length, or 0 if the bytes there are not a valid sequence.
std::size_t DecodeUtf8(const std::string& text, std::size_t i, std::uint32_t* code_point) {
  const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(text[i + k]); };
  const unsigned char lead = byte(0);
  if (lead < 0x80) {
    *code_point = lead;
    return 1;
  }
  std::size_t length = 0;
  std::uint32_t value = 0, minimum = 0;
  if (lead >= 0xC2 && lead <= 0xDF) {
    length = 2, value = lead & 0x1Fu, minimum = 0x80;
  } else if (lead >= 0xE0 && lead <= 0xEF) {
    length = 3, value = lead & 0x0Fu, minimum = 0x800;
  } else if (lead >= 0xF0 && lead <= 0xF4) {
    length = 4, value = lead & 0x07u, minimum = 0x10000;
  } else {
    return 0;
  }
  if (i + length > text.size()) return 0;
  for (std::size_t k = 1; k < length; ++k) {
    if ((byte(k) & 0xC0u) != 0x80u) return 0;
    value = (value << 6) | (byte(k) & 0x3Fu);
  }
  if (value < minimum || value > 0x10FFFF || (value >= 0xD800 && value <= 0xDFFF)) return 0;
  *code_point = value;
  return length;
}

bool IsTomlWhitespaceOrNewline(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

std::string CodePointName(std::uint32_t code_point) {
  char name[16];
  std::snprintf(name, sizeof name, "U+%04X", static_cast<unsigned>(code_point));
  return name;
}

}  // namespace

void ScreenTomlText(const std::string& text, const std::string& source) {
  Context context = Context::kCode;
  // In a basic string: the previous character was a backslash (the next one is escaped).
  bool escape_pending = false;
  // In a multi-line basic string: after a backslash followed by whitespace (a line-ending
  // backslash), up to the next non-whitespace character.
  bool trimming = false;
  std::size_t line = 1, column = 1;
  const auto fail = [&](const auto&... what) {
    ThrowInvalidArgument(source, ":", line, ":", column, ": ", what...);
  };
  const auto starts = [&](std::size_t i, const char* token) {
    return text.compare(i, 3, token) == 0;
  };
  for (std::size_t i = 0; i < text.size();) {
    std::uint32_t code_point = 0;
    const std::size_t length = DecodeUtf8(text, i, &code_point);
    if (length == 0) {
      char byte_name[8];
      std::snprintf(byte_name, sizeof byte_name, "0x%02X", static_cast<unsigned char>(text[i]));
      fail("invalid UTF-8 (byte ", byte_name, "); scene files are UTF-8 text");
    }
    const char c = static_cast<char>(text[i]);
    std::size_t advance = length;
    if (length > 1) {
      if (context == Context::kCode) {
        fail("character ", CodePointName(code_point),
             " outside a string or comment (keys, values and separators are ASCII; put text "
             "in quotes)");
      }
      if (escape_pending || trimming) {
        fail("character ", CodePointName(code_point),
             " right after a backslash in a string (escapes are ASCII, e.g. \\u00B0 for a "
             "degree sign)");
      }
    } else if (escape_pending) {
      escape_pending = false;
      // A backslash followed by whitespace ends the line in a multi-line basic string.
      trimming = context == Context::kMultiBasic && IsTomlWhitespaceOrNewline(c);
    } else if (trimming && IsTomlWhitespaceOrNewline(c)) {
      // still trimming
    } else {
      trimming = false;
      switch (context) {
        case Context::kCode:
          if (c == '#') {
            context = Context::kComment;
          } else if (c == '"') {
            context = starts(i, "\"\"\"") ? Context::kMultiBasic : Context::kBasic;
          } else if (c == '\'') {
            context = starts(i, "'''") ? Context::kMultiLiteral : Context::kLiteral;
          }
          if (context == Context::kMultiBasic || context == Context::kMultiLiteral) advance = 3;
          break;
        case Context::kComment:
          if (c == '\n') context = Context::kCode;
          break;
        case Context::kBasic:
          if (c == '\\') escape_pending = true;
          if (c == '"' || c == '\n') context = Context::kCode;  // unterminated: toml++ says so
          break;
        case Context::kLiteral:
          if (c == '\'' || c == '\n') context = Context::kCode;
          break;
        case Context::kMultiBasic:
        case Context::kMultiLiteral: {
          const bool basic = context == Context::kMultiBasic;
          if (basic && c == '\\') {
            escape_pending = true;
          } else if (starts(i, basic ? "\"\"\"" : "'''")) {
            // The delimiter may be preceded by up to two quotes of the content ("""a"""").
            advance = 3;
            for (int extra = 0; extra < 2 && i + advance < text.size() && text[i + advance] == c;
                 ++extra) {
              ++advance;
            }
            context = Context::kCode;
          }
          break;
        }
      }
    }
    for (std::size_t k = 0; k < advance; ++k) {
      if (text[i + k] == '\n') {
        ++line;
        column = 1;
      } else if ((static_cast<unsigned char>(text[i + k]) & 0xC0u) != 0x80u) {
        ++column;  // count code points, not continuation bytes
      }
    }
    i += advance;
  }
}

}  // namespace moreau::detail

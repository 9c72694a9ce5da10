#pragma once
// Enumerations that are spelled in files, on the wire and in logs: one table per enumeration
// gives each value its name, and both directions read that table, so each name is written once.

#include <array>
#include <cstddef>
#include <optional>
#include <string_view>

namespace scp {

template <class E>
struct Named {
  E value;
  const char* name;
};

template <class E, std::size_t N>
using NameTable = std::array<Named<E>, N>;

template <class E, std::size_t N>
constexpr const char* name_of(const NameTable<E, N>& table, E value) noexcept {
  for (const auto& entry : table) {
    if (entry.value == value) return entry.name;
  }
  return "unknown";
}

template <class E, std::size_t N>
constexpr std::optional<E> value_of(const NameTable<E, N>& table, std::string_view name) noexcept {
  for (const auto& entry : table) {
    if (name == entry.name) return entry.value;
  }
  return std::nullopt;
}

}  // namespace scp

#pragma once
// PLUS device-set configuration XML: the calibration transforms of <CoordinateDefinitions>
// (`<Transform From="Image" To="Probe" Matrix="16 numbers"/>`), read and written; a PLUS
// calibration result (*.results.xml) is read the same way.
#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/core/status.hpp"

namespace sonoshape::acquisition {

/// One <Transform> of <CoordinateDefinitions>: maps `from` coordinates into `to` (PLUS
/// FromToTo naming; ImageToProbe maps pixels to mm and includes the pixel spacing).
struct PlusTransform {
  std::string from;
  std::string to;
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();  ///< row-major in the file
  std::optional<double> error;  ///< the calibration's `Error` attribute, when given
  std::string date;             ///< the `Date` attribute, when given
};

/// The coordinate definitions of a PLUS configuration file.
struct PlusConfig {
  std::vector<PlusTransform> transforms;

  /// The transform `from` -> `to`: as stored, or the inverse of a stored `to` -> `from`.
  /// Fails, listing the transforms there are, when neither is defined.
  Result<Eigen::Matrix4d> transform(const std::string& from, const std::string& to) const;
};

/// Reads the <CoordinateDefinitions> of a PLUS configuration (root <PlusConfiguration>), or the
/// <CalibrationResults> of a PLUS calibration result (root <ProbeCalibrationResult>, the
/// `*.results.xml` of fCal and the TRUS template calibration). Fails with the file and element
/// on XML syntax errors, another root, and Transform elements without From/To or whose Matrix
/// is not 16 numbers.
Result<PlusConfig> read_plus_config(const std::filesystem::path& path);

/// Shortcut: the `ImageToProbe` calibration of a configuration file.
Result<Eigen::Matrix4d> read_image_to_probe(const std::filesystem::path& path);

/// Writes a minimal PLUS configuration holding `config`'s transforms (a sidecar calibration
/// next to a sequence file), with `description` as an XML comment. Fails on I/O errors.
Status write_plus_config(const PlusConfig& config, const std::filesystem::path& path,
                         const std::string& description = "");

}  // namespace sonoshape::acquisition

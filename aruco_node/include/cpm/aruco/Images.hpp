#pragma once
#include <cpm/aruco/Camera.hpp>

#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace cpm::aruco {

/// Writes an image (the format from the file's extension: .png, .jpg, …); throws cpm::Error
/// naming `path` when it cannot.
void write_image(const std::string& path, const cv::Mat& image);

/// An image read as grey, of the camera's size; throws cpm::Error naming `path` when it cannot be
/// read or its size is not the camera file's.
cv::Mat read_camera_image(const std::string& path, const Camera& camera);

/// The images in a folder (.png, .jpg, .jpeg, .bmp, .pgm, .ppm, .tif, .tiff), in name order.
/// Throws cpm::Error naming the folder when it is not one or holds no image.
std::vector<std::string> list_images(const std::string& folder);

}  // namespace cpm::aruco

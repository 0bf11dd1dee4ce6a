!> Tests of the slicing kernel: plane validation, exact areas of sphere sections (with a periodic
!> image across a box face), shell layers grown at slicing time, and the labelling rules.
module test_slicing
   use anm_core_kinds, only: wp, pi
   use anm_core_error, only: error_type
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion
   use anm_slicing_plane, only: slice_plane_type, new_slice_plane, new_axis_plane, pixel_center
   use anm_slicing_form, only: slice_form_type, new_slice_form
   use anm_slicing_kernel, only: slice_labels, slice_stats_type
   use anm_slicing_shells, only: build_shell_forms
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_slicing

contains

   !> Tests of this suite.
   subroutine collect_slicing(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("plane: bad axes and pixel size are errors", test_plane_errors), &
              new_unittest("plane: pixel centres", test_pixel_center), &
              new_unittest("sphere section area across a periodic face", test_sphere_area), &
              new_unittest("shell layer of a sphere: area and particle wins", test_sphere_shell)]
   end subroutine collect_slicing

   subroutine sphere(sh, r)
      type(sh_expansion_type), intent(out) :: sh
      real(wp), intent(in) :: r
      complex(wp) :: c(0:0, 0:0)
      c(0, 0) = cmplx(r * sqrt(4.0_wp * pi), 0.0_wp, wp)
      call new_sh_expansion(sh, c, 0)
   end subroutine sphere

   subroutine test_plane_errors(error)
      type(error_type), allocatable, intent(out) :: error
      type(slice_plane_type) :: plane
      type(error_type), allocatable :: e
      call new_slice_plane(plane, [0.0_wp, 0.0_wp, 0.0_wp], [1.0_wp, 0.0_wp, 0.0_wp], [0.5_wp, 0.5_wp, 0.0_wp], &
                           [1.0_wp, 1.0_wp], 0.1_wp, e)
      call check(error, allocated(e), "non-orthonormal axes rejected")
      if (allocated(error)) return
      call new_axis_plane(plane, 3, 1.0_wp, [1.0_wp, 1.0_wp], -0.1_wp, e)
      call check(error, allocated(e), "negative pixel rejected")
      if (allocated(error)) return
      call new_axis_plane(plane, 4, 1.0_wp, [1.0_wp, 1.0_wp], 0.1_wp, e)
      call check(error, allocated(e), "axis 4 rejected")
   end subroutine test_plane_errors

   subroutine test_pixel_center(error)
      type(error_type), allocatable, intent(out) :: error
      type(slice_plane_type) :: plane
      real(wp) :: x(3)
      call new_axis_plane(plane, 1, 2.0_wp, [4.0_wp, 3.0_wp], 0.5_wp, error)
      if (allocated(error)) return
      call check(error, plane%nu == 8 .and. plane%nv == 6, "pixel counts")
      if (allocated(error)) return
      x = pixel_center(plane, 2, 3)
      call check(error, maxval(abs(x - [2.0_wp, 0.75_wp, 1.25_wp])) < 1.0e-14_wp, "centre of pixel (2, 3)")
   end subroutine test_pixel_center

   subroutine test_sphere_area(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: sh
      type(slice_form_type) :: forms(1)
      type(slice_plane_type) :: planes(1)
      type(slice_stats_type) :: st
      integer, allocatable :: part(:, :, :), lay(:, :, :), own(:, :, :)
      integer :: shell_form(0, 1)
      real(wp) :: rot(3, 3, 1), area, pix
      call sphere(sh, 1.0_wp)
      call new_slice_form(forms(1), sh, error)
      if (allocated(error)) return
      pix = 0.01_wp
      call new_axis_plane(planes(1), 3, 2.5_wp, [4.0_wp, 4.0_wp], pix, error)
      if (allocated(error)) return
      allocate (part(400, 400, 1), lay(400, 400, 1), own(400, 400, 1))
      rot = 0.0_wp
      rot(1, 1, 1) = 1.0_wp
      rot(2, 2, 1) = 1.0_wp
      rot(3, 3, 1) = 1.0_wp
      ! centre 0.2 mm from the x = 0 face, 0.5 mm off the plane: section radius sqrt(0.75)
      call slice_labels(planes, forms, [1], shell_form, reshape([0.2_wp, 2.0_wp, 2.0_wp], [3, 1]), rot, [1.0_wp], &
                        [4.0_wp, 4.0_wp, 4.0_wp], .true., part, lay, own, st, error)
      if (allocated(error)) return
      area = count(part == 1) * pix**2
      call check(error, area, 0.75_wp * pi, "section area", rel=2.0e-3_wp)
      if (allocated(error)) return
      call check(error, count(part(381:400, :, 1) == 1) > 0, "periodic image at the x = 4 mm side")
   end subroutine test_sphere_area

   subroutine test_sphere_shell(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: sh(1)
      type(sh_expansion_type), allocatable :: outers(:, :)
      type(slice_form_type) :: forms(3)
      type(slice_plane_type) :: planes(1)
      type(slice_stats_type) :: st
      integer, allocatable :: part(:, :, :), lay(:, :, :), own(:, :, :)
      real(wp) :: rot(3, 3, 1), pix, a1, a2
      call sphere(sh(1), 1.0_wp)
      call build_shell_forms(sh, [1], reshape([0.1_wp, 0.3_wp], [2, 1]), outers, error)
      if (allocated(error)) return
      call new_slice_form(forms(1), sh(1), error)
      if (allocated(error)) return
      call new_slice_form(forms(2), outers(1, 1), error)
      if (allocated(error)) return
      call new_slice_form(forms(3), outers(2, 1), error)
      if (allocated(error)) return
      pix = 0.01_wp
      call new_axis_plane(planes(1), 3, 2.0_wp, [4.0_wp, 4.0_wp], pix, error)
      if (allocated(error)) return
      allocate (part(400, 400, 1), lay(400, 400, 1), own(400, 400, 1))
      rot = 0.0_wp
      rot(1, 1, 1) = 1.0_wp
      rot(2, 2, 1) = 1.0_wp
      rot(3, 3, 1) = 1.0_wp
      call slice_labels(planes, forms, [1], reshape([2, 3], [2, 1]), reshape([2.0_wp, 2.0_wp, 2.0_wp], [3, 1]), rot, &
                        [1.0_wp], [4.0_wp, 4.0_wp, 4.0_wp], .false., part, lay, own, st, error)
      if (allocated(error)) return
      a1 = count(lay == 1) * pix**2
      a2 = count(lay == 2) * pix**2
      call check(error, a1, pi * (1.1_wp**2 - 1.0_wp), "layer area", rel=1.0e-2_wp)
      if (allocated(error)) return
      call check(error, a2, pi * (1.3_wp**2 - 1.1_wp**2), "layer area", rel=1.0e-2_wp)
      if (allocated(error)) return
      call check(error, all(lay == 0 .or. part == 0), "no layer on particle pixels")
   end subroutine test_sphere_shell
end module test_slicing

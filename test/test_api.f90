!> Tests of the f2py adapter (anm_api_slice) through its explicit-shape interface, as Python calls
!> it: radii against closed-form spherical harmonics, the geometry of a sphere against the exact
!> values, and the status/message contract of bad input.
module test_api
   use, intrinsic :: iso_c_binding, only: c_double, c_int
   use anm_core_kinds, only: wp, pi
   use anm_core_error, only: error_type
   use anm_api_slice, only: api_sh_radius, api_geometry
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_api

   !> Rows of coefficients (n <= 1: four rows in the NIST line order 00, 11, 10, 1-1).
   integer, parameter :: nrow = 4

contains

   !> Tests of this suite.
   subroutine collect_api(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("api_sh_radius: r = 2 + c Y_1^0 (closed form)", test_radius_closed_form), &
              new_unittest("api_sh_radius: the order truncates the expansion", test_radius_order), &
              new_unittest("api_geometry: sphere of radius 2 (exact volume, area, L = W = T)", test_geometry_sphere), &
              new_unittest("api: bad shape index and zero direction give a status and a message", test_bad_input)]
   end subroutine collect_api

   !> Coefficients of r = 2 + c Y_1^0: a_00 = 2 sqrt(4 pi) (Y_0^0 = 1/sqrt(4 pi)), a_10 = c.
   pure function rows_of(c) result(coeffs)
      real(wp), intent(in) :: c
      real(c_double) :: coeffs(2, nrow, 1)
      coeffs = 0.0_c_double
      coeffs(1, 1, 1) = 2.0_wp * sqrt(4.0_wp * pi)
      coeffs(1, 3, 1) = c
   end function rows_of

   subroutine test_radius_closed_form(error)
      type(error_type), allocatable, intent(out) :: error
      real(c_double) :: dirs(3, 4), r(4), u(3)
      integer(c_int) :: status
      character(len=512) :: message
      integer :: k
      dirs = reshape([0.0_wp, 0.0_wp, 1.0_wp, 1.0_wp, 0.0_wp, 0.0_wp, 0.3_wp, -0.4_wp, 0.5_wp, &
                      0.0_wp, 2.0_wp, -3.0_wp], [3, 4])
      call api_sh_radius(nrow, 1, rows_of(0.5_wp), [1], 1, 1, 4, dirs, r, status, message)
      call check(error, status, 0, "status")
      if (allocated(error)) return
      do k = 1, 4
         u = dirs(:, k) / norm2(dirs(:, k))
         ! Y_1^0 = sqrt(3 / (4 pi)) cos(theta)
         call check(error, r(k), 2.0_wp + 0.5_wp * sqrt(3.0_wp / (4.0_wp * pi)) * u(3), "r", thr=1.0e-13_wp)
         if (allocated(error)) return
      end do
   end subroutine test_radius_closed_form

   subroutine test_radius_order(error)
      type(error_type), allocatable, intent(out) :: error
      real(c_double) :: r(1)
      integer(c_int) :: status
      character(len=512) :: message
      call api_sh_radius(nrow, 1, rows_of(0.5_wp), [1], 1, 0, 1, reshape([0.0_wp, 0.0_wp, 1.0_wp], [3, 1]), r, &
                         status, message)
      call check(error, status, 0, "status")
      if (allocated(error)) return
      call check(error, r(1), 2.0_wp, "r at order 0", thr=1.0e-13_wp)
   end subroutine test_radius_order

   subroutine test_geometry_sphere(error)
      type(error_type), allocatable, intent(out) :: error
      real(c_double) :: props(8, 1)
      integer(c_int) :: status
      character(len=512) :: message
      call api_geometry(nrow, 1, rows_of(0.0_wp), [1], 1, [1], [1], props, status, message)
      call check(error, status, 0, "status")
      if (allocated(error)) return
      call check(error, props(1, 1), 32.0_wp / 3.0_wp * pi, "volume", rel=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, props(2, 1), 16.0_wp * pi, "area", rel=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, props(3, 1), 4.0_wp, "length", rel=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, props(4, 1), 4.0_wp, "width", rel=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, props(5, 1), 4.0_wp, "thickness", rel=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, props(6, 1), 4.0_wp, "equivalent diameter", rel=1.0e-6_wp)
   end subroutine test_geometry_sphere

   subroutine test_bad_input(error)
      type(error_type), allocatable, intent(out) :: error
      real(c_double) :: r(1)
      integer(c_int) :: status
      character(len=512) :: message
      call api_sh_radius(nrow, 1, rows_of(0.0_wp), [1], 2, 1, 1, reshape([0.0_wp, 0.0_wp, 1.0_wp], [3, 1]), r, &
                         status, message)
      call check(error, status /= 0 .and. index(message, "shape index out of range") > 0, &
                 "shape 2 of 1 accepted: '"//trim(message)//"'")
      if (allocated(error)) return
      call api_sh_radius(nrow, 1, rows_of(0.0_wp), [1], 1, 1, 1, reshape([0.0_wp, 0.0_wp, 0.0_wp], [3, 1]), r, &
                         status, message)
      call check(error, status /= 0 .and. index(message, "zero direction") > 0, &
                 "zero direction accepted: '"//trim(message)//"'")
      if (allocated(error)) return
      call api_sh_radius(nrow, 1, rows_of(0.0_wp), [3], 1, 1, 1, reshape([0.0_wp, 0.0_wp, 1.0_wp], [3, 1]), r, &
                         status, message)
      call check(error, status /= 0 .and. index(message, "nmax") > 0, "nmax 3 with 4 rows accepted")
   end subroutine test_bad_input
end module test_api

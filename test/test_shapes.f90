!> Tests of shape input and the shape generators: the NIST reader (a real file and every kind of
!> malformed file), star-shapedness, the exact sphere and ellipsoid (volume 4 pi abc / 3, area
!> from elliptic integrals), and the synthetic generator against the real MA111-7-coarse set.
module test_shapes
   use anm_core_kinds, only: wp, pi, i8
   use anm_core_error, only: error_type, error_code
   use anm_sh_expansion, only: sh_expansion_type
   use anm_shapes_nist, only: read_nist_shape, write_nist_shape
   use anm_shapes_library, only: shape_set_type, load_shapes, load_shape_file, synthetic_shapes
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_shapes_synthetic, only: synthetic_params_type, make_synthetic_shape
   use anm_shapes_star, only: min_radius
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_testing, only: unittest_type, new_unittest, check, shapes_dir
   implicit none
   private
   public :: collect_shapes

   character(len=*), parameter :: tmpdir = "build/test-tmp"

contains

   !> Tests of this suite.
   subroutine collect_shapes(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("read a NIST coefficient file", test_read_nist), &
              new_unittest("write and re-read a shape", test_write_read), &
              new_unittest("truncated file is refused", test_truncated), &
              new_unittest("non-numeric line is refused", test_non_numeric), &
              new_unittest("missing coefficient is refused", test_missing), &
              new_unittest("wrong field count is refused", test_field_count), &
              new_unittest("negative radius is refused (not star-shaped)", test_negative_radius), &
              new_unittest("missing file and folder are refused", test_missing_file), &
              new_unittest("empty file is refused", test_empty), &
              new_unittest("sphere: exact volume and area", test_sphere), &
              new_unittest("ellipsoid 3:2:1 at order 30: volume and area", test_ellipsoid), &
              new_unittest("synthetic shapes: star-shaped, L/T and W/T like MA111-7-coarse", test_synthetic), &
              new_unittest("synthetic shapes are reproducible per (seed, index)", test_synthetic_repro)]
   end subroutine collect_shapes

   subroutine write_lines(name, lines)
      character(len=*), intent(in) :: name
      character(len=*), intent(in) :: lines(:)
      integer :: unit, i
      call execute_command_line("mkdir -p "//tmpdir)
      open (newunit=unit, file=tmpdir//"/"//name, status="replace", action="write")
      do i = 1, size(lines)
         write (unit, '(a)') trim(lines(i))
      end do
      close (unit)
   end subroutine write_lines

   !> Expect `path` to be refused with class `stat` and a message containing `part`.
   subroutine expect_refused(error, path, stat, part)
      type(error_type), allocatable, intent(out) :: error
      character(len=*), intent(in) :: path, part
      integer, intent(in) :: stat
      type(error_type), allocatable :: err
      type(sh_expansion_type) :: s
      call load_shape_file(path, s, err)
      call check(error, allocated(err), "no error for "//path)
      if (allocated(error)) return
      print '(a)', "        refused as expected: "//err%message
      call check(error, err%stat, stat, "error class")
      if (allocated(error)) return
      call check(error, index(err%message, path) > 0, "message must name the file: "//err%message)
      if (allocated(error)) return
      call check(error, index(err%message, part) > 0, "message must contain '"//part//"': "//err%message)
   end subroutine expect_refused

   subroutine test_read_nist(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: s
      integer :: nmax
      call shapes_dir(dir, error)
      if (allocated(error)) return
      call read_nist_shape(dir//"/MA111-7-coarse/MA111-7-coarse-anm-00002.dat", s, error, nmax)
      if (allocated(error)) return
      call check(error, nmax, 30, "degree")
      if (allocated(error)) return
      ! first lines: 0 0 26.4181362679 0; 1 1 -0.1019398010 0.1965024594 -> A11 = 2 Re, B11 = -2 Im
      call check(error, s%a(0, 0), 26.4181362679_wp, "a00", rel=1.0e-14_wp)
      if (allocated(error)) return
      call check(error, s%a(1, 1), -0.2038796020_wp, "A11", rel=1.0e-12_wp)
      if (allocated(error)) return
      call check(error, s%b(1, 1), -0.3930049188_wp, "B11", rel=1.0e-12_wp)
   end subroutine test_read_nist

   subroutine test_write_read(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s, s2
      s = ellipsoid_shape(2.0_wp, 1.5_wp, 1.0_wp, 8)
      call execute_command_line("mkdir -p "//tmpdir)
      call write_nist_shape(tmpdir//"/ell.dat", s, error)
      if (allocated(error)) return
      call load_shape_file(tmpdir//"/ell.dat", s2, error)
      if (allocated(error)) return
      call check(error, s2%nmax, 8, "degree")
      if (allocated(error)) return
      ! the file keeps 10 decimals
      call check(error, maxval(abs(s2%a - s%a)) + maxval(abs(s2%b - s%b)), 0.0_wp, "coefficients", thr=2.0e-10_wp)
   end subroutine test_write_read

   subroutine test_truncated(error)
      type(error_type), allocatable, intent(out) :: error
      call write_lines("truncated.dat", [character(len=48) :: &
                       "   0   0        1.0000000000        0.0000000000", &
                       "   1   1        0.0100000000        0.0000000000", &
                       "   1   0        0.0100000000        0.0000000000"])
      call expect_refused(error, tmpdir//"/truncated.dat", error_code%format, "truncated")
   end subroutine test_truncated

   subroutine test_non_numeric(error)
      type(error_type), allocatable, intent(out) :: error
      call write_lines("nonnumeric.dat", [character(len=48) :: &
                       "   0   0        1.0000000000        0.0000000000", &
                       "   1   1        0.01000x0000        0.0000000000"])
      call expect_refused(error, tmpdir//"/nonnumeric.dat", error_code%format, ":2:")
   end subroutine test_non_numeric

   subroutine test_missing(error)
      type(error_type), allocatable, intent(out) :: error
      call write_lines("missing.dat", [character(len=48) :: &
                       "   0   0        1.0000000000        0.0000000000", &
                       "   1   1        0.0100000000        0.0000000000", &
                       "   1  -1       -0.0100000000        0.0000000000"])
      call expect_refused(error, tmpdir//"/missing.dat", error_code%format, "missing")
   end subroutine test_missing

   subroutine test_field_count(error)
      type(error_type), allocatable, intent(out) :: error
      call write_lines("fields.dat", [character(len=48) :: &
                       "   0   0        1.0000000000", &
                       "   1   1        0.0100000000        0.0000000000"])
      call expect_refused(error, tmpdir//"/fields.dat", error_code%format, ":1:")
   end subroutine test_field_count

   subroutine test_negative_radius(error)
      type(error_type), allocatable, intent(out) :: error
      ! r = 1/(2 sqrt pi) * 1 + 3 sqrt(3/4pi) cos(theta) is negative near theta = pi
      call write_lines("negative.dat", [character(len=48) :: &
                       "   0   0        1.0000000000        0.0000000000", &
                       "   1   1        0.0000000000        0.0000000000", &
                       "   1   0        3.0000000000        0.0000000000", &
                       "   1  -1        0.0000000000        0.0000000000"])
      call expect_refused(error, tmpdir//"/negative.dat", error_code%not_star, "not a star-shaped")
   end subroutine test_negative_radius

   subroutine test_missing_file(error)
      type(error_type), allocatable, intent(out) :: error
      type(shape_set_type) :: set
      type(error_type), allocatable :: err
      call load_shapes(tmpdir//"/no-such-file.dat", set, err)
      call check(error, allocated(err), "missing file accepted")
      if (allocated(error)) return
      call check(error, index(err%message, "no-such-file.dat") > 0, "message names the file: "//err%message)
   end subroutine test_missing_file

   subroutine test_empty(error)
      type(error_type), allocatable, intent(out) :: error
      integer :: unit
      call execute_command_line("mkdir -p "//tmpdir)
      open (newunit=unit, file=tmpdir//"/empty.dat", status="replace")
      close (unit)
      call expect_refused(error, tmpdir//"/empty.dat", error_code%format, "empty")
   end subroutine test_empty

   subroutine test_sphere(error)
      type(error_type), allocatable, intent(out) :: error
      type(shape_geometry_type) :: g
      real(wp), parameter :: radius = 2.5_wp
      call compute_geometry(sphere_shape(radius), g)
      call check(error, g%volume, 4.0_wp / 3.0_wp * pi * radius**3, "volume", rel=1.0e-14_wp)
      if (allocated(error)) return
      call check(error, g%area, 4.0_wp * pi * radius**2, "area", rel=1.0e-12_wp)
      if (allocated(error)) return
      call check(error, g%length, 2 * radius, "length", rel=1.0e-9_wp)
      if (allocated(error)) return
      call check(error, g%width, 2 * radius, "width", rel=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, g%thickness, 2 * radius, "thickness", rel=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, g%extent_hi(3), radius, "extent", rel=1.0e-12_wp)
   end subroutine test_sphere

   subroutine test_ellipsoid(error)
      type(error_type), allocatable, intent(out) :: error
      type(shape_geometry_type) :: g
      ! exact area of the 3:2:1 ellipsoid: 2 pi c^2 + 2 pi a b (E(phi,k) sin^2 phi + F(phi,k) cos^2 phi)
      ! / sin phi, cos phi = c/a, k^2 = a^2 (b^2 - c^2) / (b^2 (a^2 - c^2)) (mpmath, 30 digits)
      real(wp), parameter :: area_exact = 48.8821463025820596957_wp
      call compute_geometry(ellipsoid_shape(3.0_wp, 2.0_wp, 1.0_wp, 30), g)
      print '(a,es10.3,a,es10.3)', "        ellipsoid 3:2:1 order 30: volume rel. error ", &
         g%volume / (4.0_wp * pi * 2.0_wp) - 1.0_wp, ", area rel. error ", g%area / area_exact - 1.0_wp
      call check(error, g%volume, 4.0_wp * pi * 3.0_wp * 2.0_wp * 1.0_wp / 3.0_wp, "volume", rel=1.0e-6_wp)
      if (allocated(error)) return
      call check(error, g%area, area_exact, "area", rel=1.0e-3_wp)
      if (allocated(error)) return
      call check(error, g%length, 6.0_wp, "length", rel=2.0e-3_wp)
      if (allocated(error)) return
      call check(error, g%width, 4.0_wp, "width", rel=2.0e-3_wp)
      if (allocated(error)) return
      call check(error, g%thickness, 2.0_wp, "thickness", rel=2.0e-3_wp)
   end subroutine test_ellipsoid

   subroutine test_synthetic(error)
      type(error_type), allocatable, intent(out) :: error
      ! MA111-7-coarse.sst: Mean L/T = 2.401 +- 0.800, Mean W/T = 1.688 +- 0.478 (207 particles)
      real(wp), parameter :: lt_real = 2.401_wp, wt_real = 1.688_wp
      integer, parameter :: nshape = 48
      type(synthetic_params_type) :: par
      type(shape_set_type) :: set
      type(shape_geometry_type) :: g(nshape)
      real(wp) :: lt, wt, rmin, th, ph
      integer :: k
      call synthetic_shapes(par, 2026_i8, nshape, set, error)
      if (allocated(error)) return
      !$omp parallel do default(shared) private(k) schedule(dynamic)
      do k = 1, nshape
         call compute_geometry(set%shapes(k), g(k))
      end do
      !$omp end parallel do
      do k = 1, nshape
         call min_radius(set%shapes(k), rmin, th, ph)
         call check(error, rmin > 0.0_wp, "synthetic shape not star-shaped")
         if (allocated(error)) return
      end do
      lt = sum(g%length / g%thickness) / nshape
      wt = sum(g%width / g%thickness) / nshape
      print '(a,f6.3,a,f6.3,a,f6.3,a,f6.3,a)', "        synthetic mean L/T ", lt, " (real ", lt_real, &
         "), mean W/T ", wt, " (real ", wt_real, ")"
      call check(error, lt, lt_real, "mean L/T", rel=0.10_wp)
      if (allocated(error)) return
      call check(error, wt, wt_real, "mean W/T", rel=0.10_wp)
   end subroutine test_synthetic

   subroutine test_synthetic_repro(error)
      type(error_type), allocatable, intent(out) :: error
      type(synthetic_params_type) :: par
      type(sh_expansion_type) :: a, b, c
      call make_synthetic_shape(par, 5_i8, 3, a, error)
      if (allocated(error)) return
      call make_synthetic_shape(par, 5_i8, 3, b, error)
      if (allocated(error)) return
      call make_synthetic_shape(par, 5_i8, 4, c, error)
      if (allocated(error)) return
      call check(error, all(a%a == b%a) .and. all(a%b == b%b), "same (seed, index) differs")
      if (allocated(error)) return
      call check(error, any(a%a /= c%a), "different index gives the same shape")
   end subroutine test_synthetic_repro
end module test_shapes

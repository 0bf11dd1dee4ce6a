!> Tests of the parking infrastructure: the hierarchical cell list against brute force for
!> sizes differing 1000:1, in periodic and non-periodic boxes.
module test_parking
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng
   use anm_parking_cell_list, only: cell_list_type, new_cell_list
   use anm_io_model, only: model_type
   use anm_audit_verify, only: verify_report_type, verify_model
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_geometry_rotation, only: random_rotation
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_parking

contains

   !> Tests of this suite.
   subroutine collect_parking(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("cell list equals brute force, periodic, sizes 1000:1", test_cells_periodic), &
              new_unittest("cell list equals brute force, walls", test_cells_walls), &
              new_unittest("cell list finds all images in a small periodic box", test_cells_images), &
              new_unittest("verify: separated spheres pass", test_verify_clear), &
              new_unittest("verify: overlapping spheres fail with the exact depth", test_verify_overlap), &
              new_unittest("verify: overlap across the periodic boundary", test_verify_periodic), &
              new_unittest("verify: a particle through a wall fails", test_verify_wall)]
   end subroutine collect_parking

   subroutine run_case(error, periodic, box, rmin, rmax, n, nq)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in) :: periodic
      real(wp), intent(in) :: box(3), rmin, rmax
      integer, intent(in) :: n, nq
      type(cell_list_type) :: cl
      type(rng_type) :: rng
      real(wp), allocatable :: c(:, :), rho(:), shift(:, :)
      integer, allocatable :: cand(:)
      real(wp) :: q(3), rq, d(3), lim
      integer :: i, k, ncand, nbrute, s1, s2, s3, hits
      call new_rng(rng, 11_i8, 0_i8)
      allocate (c(3, n), rho(n))
      call new_cell_list(cl, box, periodic, rmin)
      do i = 1, n
         c(:, i) = [rng%uniform(), rng%uniform(), rng%uniform()] * box
         ! log-uniform radii between rmin and rmax
         rho(i) = rmin * (rmax / rmin)**rng%uniform()
         call cl%insert(i, c(:, i), rho(i))
      end do
      do k = 1, nq
         q = [rng%uniform(), rng%uniform(), rng%uniform()] * box
         rq = rmin * (rmax / rmin)**rng%uniform()
         call cl%query(q, rq, c, rho, cand, shift, ncand)
         nbrute = 0
         do i = 1, n
            lim = rq + rho(i)
            d = c(:, i) - q
            do s3 = -1, 1
               do s2 = -1, 1
                  do s1 = -1, 1
                     if (.not. periodic .and. any([s1, s2, s3] /= 0)) cycle
                     if (sum((d + [s1, s2, s3] * box)**2) < lim * lim) nbrute = nbrute + 1
                  end do
               end do
            end do
         end do
         hits = 0
         do i = 1, ncand
            d = c(:, cand(i)) + shift(:, i) - q
            if (sum(d**2) < (rq + rho(cand(i)))**2) hits = hits + 1
         end do
         call check(error, ncand, nbrute, "candidates vs brute force")
         if (allocated(error)) return
         call check(error, hits, ncand, "every candidate really intersects")
         if (allocated(error)) return
      end do
   end subroutine run_case

   subroutine test_cells_periodic(error)
      type(error_type), allocatable, intent(out) :: error
      call run_case(error, .true., [20.0_wp, 20.0_wp, 20.0_wp], 0.005_wp, 5.0_wp, 3000, 800)
   end subroutine test_cells_periodic

   subroutine test_cells_walls(error)
      type(error_type), allocatable, intent(out) :: error
      call run_case(error, .false., [20.0_wp, 15.0_wp, 10.0_wp], 0.01_wp, 2.0_wp, 3000, 2000)
   end subroutine test_cells_walls

   subroutine test_cells_images(error)
      type(error_type), allocatable, intent(out) :: error
      call run_case(error, .true., [4.0_wp, 4.0_wp, 4.0_wp], 0.5_wp, 1.5_wp, 50, 500)
   end subroutine test_cells_images
   !> A model of spheres of radius 1 (shape 1) at the given centres.
   function sphere_model(centers, periodic, box) result(m)
      real(wp), intent(in) :: centers(:, :)
      logical, intent(in) :: periodic
      real(wp), intent(in) :: box(3)
      type(model_type) :: m
      type(rng_type) :: rng
      integer :: p
      call new_rng(rng, 5_i8, 0_i8)
      m%box = box
      m%periodic = periodic
      allocate (m%shapes(1), m%shape_names(1))
      m%shapes(1) = sphere_shape(1.0_wp)
      m%shape_names(1) = "sphere"
      m%np = size(centers, 2)
      m%center = centers
      allocate (m%rotation(3, 3, m%np))
      do p = 1, m%np
         m%rotation(:, :, p) = random_rotation(rng)
      end do
      m%scale = [(1.0_wp, p=1, m%np)]
      m%shape = [(1, p=1, m%np)]
      m%nmax = [(0, p=1, m%np)]
      m%sieve = [(1, p=1, m%np)]
      m%min_width = [2.0_wp]
   end function sphere_model

   subroutine test_verify_clear(error)
      type(error_type), allocatable, intent(out) :: error
      type(verify_report_type) :: rep
      ! gap of 1e-3 between the first two, the third far away
      call verify_model(sphere_model(reshape([3.0_wp, 5.0_wp, 5.0_wp, 5.001_wp, 5.0_wp, 5.0_wp, 8.0_wp, 8.0_wp, 8.0_wp], &
                                             [3, 3]), .false., [10.0_wp, 10.0_wp, 10.0_wp]), 60, rep)
      call check(error, rep%pairs_checked >= 1_i8 .and. rep%overlapping_pairs == 0_i8 .and. rep%wall_violations == 0, &
                 "clear spheres flagged")
   end subroutine test_verify_clear

   subroutine test_verify_overlap(error)
      type(error_type), allocatable, intent(out) :: error
      type(verify_report_type) :: rep
      ! centres 1.98 apart: radial penetration 0.02 exactly along the line of centres
      call verify_model(sphere_model(reshape([3.0_wp, 5.0_wp, 5.0_wp, 4.98_wp, 5.0_wp, 5.0_wp], [3, 2]), .false., &
                                     [10.0_wp, 10.0_wp, 10.0_wp]), 120, rep)
      call check(error, rep%overlapping_pairs == 1_i8, "overlap not found")
      if (allocated(error)) return
      print '(a,es10.3,a)', "        sphere overlap depth found ", rep%max_depth, " (exact 2.0e-2)"
      call check(error, rep%max_depth, 0.02_wp, "depth", thr=2.0e-3_wp)
   end subroutine test_verify_overlap

   subroutine test_verify_periodic(error)
      type(error_type), allocatable, intent(out) :: error
      type(verify_report_type) :: rep
      ! 0.5 and 9.4 along x in a periodic 10 mm box: 1.1 apart through the boundary
      call verify_model(sphere_model(reshape([0.5_wp, 5.0_wp, 5.0_wp, 9.4_wp, 5.0_wp, 5.0_wp], [3, 2]), .true., &
                                     [10.0_wp, 10.0_wp, 10.0_wp]), 60, rep)
      call check(error, rep%overlapping_pairs == 1_i8, "periodic overlap not found")
   end subroutine test_verify_periodic

   subroutine test_verify_wall(error)
      type(error_type), allocatable, intent(out) :: error
      type(verify_report_type) :: rep
      call verify_model(sphere_model(reshape([0.99_wp, 5.0_wp, 5.0_wp], [3, 1]), .false., &
                                     [10.0_wp, 10.0_wp, 10.0_wp]), 60, rep)
      call check(error, rep%wall_violations, 1, "wall crossing not found")
   end subroutine test_verify_wall
end module test_parking

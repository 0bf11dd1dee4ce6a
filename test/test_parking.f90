!> Tests of the parking infrastructure: the hierarchical cell list against brute force for
!> sizes differing 1000:1, in periodic and non-periodic boxes.
module test_parking
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng
   use anm_parking_cell_list, only: cell_list_type, new_cell_list
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
              new_unittest("cell list finds all images in a small periodic box", test_cells_images)]
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
end module test_parking

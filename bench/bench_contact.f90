!> Contact benchmark: time per pair for the EOB method and the Newton-Raphson baseline on the
!> same pairs of real MA111-7-coarse shapes at degree 14 (and 30), for pairs far apart (bounding
!> spheres overlap, centres 1.3 x contact distance), near but not touching (1.02 x) and overlapping
!> (0.98 x). The contact distance along a random direction is found by bisection on D_overlap.
!> Prints median and mean microseconds per pair for the default EOB mode, the certified EOB mode
!> and Newton-Raphson. Run: OMP_NUM_THREADS=1 fpm run bench-contact [-- NPAIR [ORDER [CLASS]]]
!> (defaults 200 pairs, degrees 14 and 30, all classes; CLASS 1 far, 2 near, 3 overlapping; giving
!> a class selects profiling: one repetition, no NR, e.g. under valgrind --tool=callgrind).
program bench_contact
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use anm_core_kinds, only: wp, i8
   use anm_core_statistics, only: median
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng
   use anm_sh_expansion, only: sh_expansion_type
   use anm_shapes_library, only: load_shape_file
   use anm_geometry_rotation, only: random_rotation
   use anm_contact_body, only: contact_body_type, new_contact_body
   use anm_contact_overlap, only: contact_method, contact_params_type, bodies_overlap, overlap_depth
   implicit none
   integer, parameter :: nshape = 4, nclass = 3
   character(len=5), parameter :: ids(nshape) = ["00002", "00009", "00035", "00061"]
   real(wp), parameter :: factor(nclass) = [1.3_wp, 1.02_wp, 0.98_wp]
   character(len=*), parameter :: label(nclass) = [character(len=12) :: "far", "near", "overlapping"]
   type(sh_expansion_type) :: shape(nshape)
   type(contact_body_type) :: body(nshape)
   type(contact_params_type) :: eob, cert, nr
   type(error_type), allocatable :: error
   type(rng_type) :: rng
   real(wp), allocatable :: rota(:, :, :), rotb(:, :, :), dstar(:), u(:, :), t_eob(:), t_nr(:)
   integer, allocatable :: ia(:), ib(:)
   integer :: k, n, c, order, io, nhit_eob, nhit_nr, nhit_cert, npair, c0, c1
   integer, allocatable :: orders(:)
   real(wp), allocatable :: t_cert(:)
   character(len=32) :: arg
   logical :: profiling
   real(wp) :: lo, hi, mid
   character(len=*), parameter :: dir = "../shared/shapes/MA111-7-coarse/MA111-7-coarse-anm-"

   nr%method = contact_method%newton_raphson
   cert%certified = .true.
   npair = 200
   orders = [14, 30]
   c0 = 1
   c1 = nclass
   profiling = .false.
   if (command_argument_count() >= 1) then
      call get_command_argument(1, arg)
      read (arg, *) npair
   end if
   if (command_argument_count() >= 2) then
      call get_command_argument(2, arg)
      read (arg, *) order
      orders = [order]
   end if
   if (command_argument_count() >= 3) then
      call get_command_argument(3, arg)
      read (arg, *) c0
      c1 = c0
      profiling = .true.
   end if
   allocate (t_cert(npair))
   allocate (rota(3, 3, npair), rotb(3, 3, npair), dstar(npair), u(3, npair), t_eob(npair), t_nr(npair))
   allocate (ia(npair), ib(npair))
   do io = 1, size(orders)
      order = orders(io)
      do k = 1, nshape
         call load_shape_file(dir//ids(k)//".dat", shape(k), error)
         if (allocated(error)) then
            write (error_unit, '(a)') error%message
            call exit(1)
         end if
         call new_contact_body(body(k), shape(k), error, nused=order)
         if (allocated(error)) then
            write (error_unit, '(a)') error%message
            call exit(1)
         end if
      end do
      call new_rng(rng, 42_i8, 1_i8)
      do n = 1, npair
         ia(n) = 1 + mod(n, nshape)
         ib(n) = 1 + mod(n / nshape, nshape)
         rota(:, :, n) = random_rotation(rng)
         rotb(:, :, n) = random_rotation(rng)
         u(:, n) = [rng%normal(), rng%normal(), rng%normal()]
         u(:, n) = u(:, n) / norm2(u(:, n))
         lo = body(ia(n))%r_min + body(ib(n))%r_min
         hi = body(ia(n))%r_max + body(ib(n))%r_max
         do k = 1, 22
            mid = 0.5_wp * (lo + hi)
            if (overlap_depth(body(ia(n)), [0.0_wp, 0.0_wp, 0.0_wp], rota(:, :, n), 1.0_wp, body(ib(n)), &
                              mid * u(:, n), rotb(:, :, n), 1.0_wp, 256) > 0.0_wp) then
               lo = mid
            else
               hi = mid
            end if
         end do
         dstar(n) = hi
      end do
      write (output_unit, '(a,i0,a,i0,a)') "# contact, degree ", order, ", ", npair, &
         " pairs of MA111-7-coarse shapes; microseconds per pair (median, mean); pairs reported overlapping"
      do c = c0, c1
         call time_method(eob, factor(c), t_eob, nhit_eob)
         call time_method(cert, factor(c), t_cert, nhit_cert)
         if (profiling) then
            t_nr = 0.0_wp
            nhit_nr = 0
         else
            call time_method(nr, factor(c), t_nr, nhit_nr)
         end if
         write (output_unit, '(a,a12,a,2f10.2,a,i4,a,2f10.2,a,i4,a,2f10.2,a,i4)') "  ", label(c), "  EOB ", &
            median(t_eob), sum(t_eob) / npair, "  hits ", nhit_eob, "   certified ", median(t_cert), &
            sum(t_cert) / npair, "  hits ", nhit_cert, "   NR ", median(t_nr), sum(t_nr) / npair, "  hits ", nhit_nr
      end do
   end do
contains
   subroutine time_method(par, f, t, nhit)
      type(contact_params_type), intent(in) :: par
      real(wp), intent(in) :: f
      real(wp), intent(out) :: t(:)
      integer, intent(out) :: nhit
      integer(i8) :: t0, t1, rate
      integer :: m, rep, nrep
      logical :: hit
      nhit = 0
      nrep = merge(20, 2, par%method == contact_method%eob)
      if (profiling) nrep = 1
      do m = 1, npair
         call system_clock(t0, rate)
         do rep = 1, nrep
            hit = bodies_overlap(body(ia(m)), [0.0_wp, 0.0_wp, 0.0_wp], rota(:, :, m), 1.0_wp, body(ib(m)), &
                                 f * dstar(m) * u(:, m), rotb(:, :, m), 1.0_wp, par)
         end do
         call system_clock(t1)
         t(m) = 1.0e6_wp * real(t1 - t0, wp) / real(rate, wp) / nrep
         if (hit) nhit = nhit + 1
      end do
   end subroutine time_method

end program bench_contact

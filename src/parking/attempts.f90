!> The attempt sequence of one particle (thesis section 2.1): the four nested randomness sources
!> shape -> [width level] -> width -> rotation -> centre, up to max_shapes, max_sizes,
!> max_orientations and max_locations of each, drawn from the particle's own random stream
!> (seed, s 2^32 + i) for particle (stream) i of sieve s, in this fixed order. The centre is
!> uniform in the box (away from the walls by the particle's inscribed radius) or, with void
!> placement, uniform over the free cells of a void grid.
!>
!> Usage:
!>     call a%start(ap, stream)
!>     do
!>        call a%next(ap, kinds, vg)
!>        if (a%done) exit
!>        if (pk%fits(a%k, a%c, a%r, a%sc, scratch)) exit
!>     end do
module anm_parking_attempts
   use anm_core_kinds, only: wp, i8
   use anm_core_random, only: rng_type, new_rng
   use anm_geometry_rotation, only: random_rotation
   use anm_parking_kinds, only: particle_kind_type, width_levels, body_holder
   use anm_parking_void_grid, only: void_grid_type
   implicit none
   private

   public :: attempt_type, attempt_params_type, first_kind_of

   !> What the attempt sequences of one sieve need (filled by the driver).
   type :: attempt_params_type
      !> Base seed and sieve (the streams are (seed, sieve 2^32 + i)).
      integer(i8) :: seed = 1_i8
      integer :: sieve = 1
      !> Budgets of the four sources.
      integer :: max_locations = 2000, max_orientations = 1, max_sizes = 1, max_shapes = 1
      !> First kind of the sieve, its number of kinds, width levels (the kinds are nlev blocks of
      !> the sieve's shapes).
      integer :: first_kind = 1, nkind = 1, nlev = 1
      !> Width range of the sieve (mm).
      real(wp) :: min_width = 1.0_wp, max_width = 1.0_wp
      !> Box edges (mm) and periodic boundaries.
      real(wp) :: box(3) = 1.0_wp
      logical :: periodic = .true.
      !> Centres from the void grid.
      logical :: void = .false.
   end type attempt_params_type

   !> The attempt sequence of one particle and its current attempt.
   type :: attempt_type
      !> The particle's stream.
      type(rng_type) :: rng
      !> Counters of the four sources (shape, size, orientation, location).
      integer :: is = 0, iz = 0, io = 0, il = 0
      !> Kind of the current shape at width level 1, and kind of the current attempt.
      integer :: kk = 0, k = 0
      !> Width (mm), scale, rotation (body to world) and centre of the current attempt.
      real(wp) :: w = 0.0_wp, sc = 0.0_wp, r(3, 3) = 0.0_wp, c(3) = 0.0_wp
      !> Attempts drawn so far (the one that finds the sequence exhausted included).
      integer(i8) :: count = 0
      !> All attempts exhausted.
      logical :: done = .false.
   contains
      !> Start the sequence of particle `stream` of the sieve.
      procedure :: start
      !> Advance by one attempt (or mark the sequence done).
      procedure :: next
   end type attempt_type

contains

   !> Start the sequence of particle `stream` (1, 2, ... within the sieve).
   subroutine start(self, ap, stream)
      !> Sequence.
      class(attempt_type), intent(out) :: self
      !> Parameters of the sieve.
      type(attempt_params_type), intent(in) :: ap
      !> Particle number within the sieve.
      integer, intent(in) :: stream
      call new_rng(self%rng, ap%seed, int(ap%sieve, i8) * 4294967296_i8 + stream)
   end subroutine start

   !> The kind of the first attempt of particle `stream` (its first draws), for building kinds
   !> before the particle runs.
   integer function first_kind_of(ap, stream) result(k)
      !> Parameters of the sieve.
      type(attempt_params_type), intent(in) :: ap
      !> Particle number within the sieve.
      integer, intent(in) :: stream
      type(attempt_type) :: a
      call a%start(ap, stream)
      call pick_shape(a, ap)
      call pick_size(a, ap)
      k = a%k
   end function first_kind_of

   !> Advance the sequence by one attempt (or mark it done): the thesis' nested order.
   subroutine next(self, ap, kinds, vg)
      !> Sequence.
      class(attempt_type), intent(inout) :: self
      !> Parameters of the sieve.
      type(attempt_params_type), intent(in) :: ap
      !> Kinds (those of the sieve's attempts built).
      type(particle_kind_type), intent(in) :: kinds(:)
      !> Void grid (read only with void placement).
      type(void_grid_type), intent(in) :: vg
      if (self%done) return
      if (self%is > 0 .and. self%il < ap%max_locations) then
         self%il = self%il + 1
      else if (self%is > 0 .and. self%io < ap%max_orientations) then
         self%io = self%io + 1
         self%il = 1
         self%r = random_rotation(self%rng)
      else if (self%is > 0 .and. self%iz < ap%max_sizes) then
         self%iz = self%iz + 1
         call new_size(self, ap, kinds)
         self%io = 1
         self%il = 1
         self%r = random_rotation(self%rng)
      else if (self%is < ap%max_shapes) then
         self%is = self%is + 1
         call pick_shape(self, ap)
         self%iz = 1
         call new_size(self, ap, kinds)
         self%io = 1
         self%il = 1
         self%r = random_rotation(self%rng)
      else
         self%done = .true.
         self%count = self%count + 1
         return
      end if
      if (ap%void) then
         self%c = void_centre(self%rng, vg)
      else
         self%c = random_centre(self%rng, ap, self%sc * kinds(body_holder(kinds, self%k))%body%r_min)
      end if
      self%count = self%count + 1
   end subroutine next

   !> Draw a shape of the sieve.
   subroutine pick_shape(a, ap)
      type(attempt_type), intent(inout) :: a
      type(attempt_params_type), intent(in) :: ap
      a%kk = ap%first_kind + a%rng%below(ap%nkind / ap%nlev) - 1
   end subroutine pick_shape

   !> Draw a new width (and width level) for the current shape.
   subroutine new_size(a, ap, kinds)
      type(attempt_type), intent(inout) :: a
      type(attempt_params_type), intent(in) :: ap
      type(particle_kind_type), intent(in) :: kinds(:)
      call pick_size(a, ap)
      a%sc = a%w / kinds(a%k)%width
   end subroutine new_size

   !> The draws of new_size: width level (kind) and width.
   subroutine pick_size(a, ap)
      type(attempt_type), intent(inout) :: a
      type(attempt_params_type), intent(in) :: ap
      integer :: lev
      if (ap%nlev > 1) then
         lev = a%rng%below(width_levels)
         a%k = a%kk + (lev - 1) * (ap%nkind / ap%nlev)
         a%w = ap%min_width + (lev - 0.5_wp) * (ap%max_width - ap%min_width) / width_levels
      else
         a%k = a%kk
         a%w = a%rng%uniform_range(ap%min_width, ap%max_width)
      end if
   end subroutine pick_size

   !> A centre uniform in the box (non-periodic: at least `margin` from the walls).
   function random_centre(gen, ap, margin) result(x)
      type(rng_type), intent(inout) :: gen
      type(attempt_params_type), intent(in) :: ap
      real(wp), intent(in) :: margin
      real(wp) :: x(3)
      integer :: d
      do d = 1, 3
         if (ap%periodic) then
            x(d) = gen%uniform() * ap%box(d)
         else
            x(d) = gen%uniform_range(margin, ap%box(d) - margin)
         end if
      end do
   end function random_centre

   !> A centre drawn uniformly from the free cells of the void grid (stale entries redrawn).
   function void_centre(gen, vg) result(x)
      type(rng_type), intent(inout) :: gen
      type(void_grid_type), intent(in) :: vg
      real(wp) :: x(3), u(4)
      integer :: tries, q
      do tries = 1, 64
         do q = 1, 4
            u(q) = gen%uniform()
         end do
         x = vg%draw(u(1), u(2), u(3), u(4))
         if (.not. vg%is_blocked(x)) exit
      end do
   end function void_centre
end module anm_parking_attempts

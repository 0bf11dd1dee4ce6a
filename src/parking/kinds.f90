!> Particle kinds: the precomputed data of one (sieve, shape[, width level]) combination (geometry
!> at the sieve's order, contact body, shell layers) and the set of them for a run, built lazily
!> (a kind is built when first needed; a kind equal to an earlier one is built once and copied;
!> the geometry and bare contact body of a (shape, order) are built once and copied to its width
!> levels, which differ only in their shells).
!>
!> The kinds of sieve s are `first(s) .. first(s) + count(s) - 1`: `nlev` blocks (width levels,
!> shells in mm) of the sieve's shapes.
!>
!> Usage:
!>     call new_kind_set(ks, kinds, params, shapes, names, first_shape, nshape, order)
!>     call ks%build(kinds, [(k, k = ks%first(s), ks%first(s) + ks%count(s) - 1)], error)
module anm_parking_kinds
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error
   use anm_core_filesystem, only: string_type
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_contact_body, only: contact_body_type, new_contact_body
   use anm_shells_build, only: shell_report_type, build_layers
   use anm_config_shells, only: shell_mode
   use anm_shells_thickness, only: thickness_unit, thickness_to_shape_units
   implicit none
   private

   public :: particle_kind_type, kind_params_type, kind_set_type, new_kind_set, width_levels

   !> Discrete widths per sieve when shell thickness is given in mm.
   integer, parameter :: width_levels = 8

   !> Precomputed data of one (sieve, shape[, width level]) combination.
   type :: particle_kind_type
      !> Index into the model's shapes.
      integer :: shape = 0
      !> Sieve.
      integer :: sieve = 0
      !> Order used.
      integer :: order = 0
      !> Width level (0: continuous widths).
      integer :: level = 0
      !> Geometry at the order used (shape units).
      real(wp) :: width = 0.0_wp, length = 0.0_wp, volume = 0.0_wp
      !> Bare particle.
      type(contact_body_type) :: body
      !> Particle plus its outermost shell (allocated with shells).
      type(contact_body_type), allocatable :: shell_body
      !> Outer surfaces of the layers (shape units) and the volume inside each.
      type(sh_expansion_type), allocatable :: layers(:)
      !> Volume inside each layer's outer surface (shape units).
      real(wp), allocatable :: layer_volume(:)
      !> Bounding radius of the largest body the overlap tests use (shape units).
      real(wp) :: r_out = 0.0_wp
      !> Radii (shape units) such that a particle of this kind, placed as a candidate, certainly
      !> overlaps a parked one whose centre is closer than scale r_in_query + scale_j r_in_parked
      !> (the inscribed radii of the bodies the shell mode tests: the overlap test's own first
      !> stage).
      real(wp) :: r_in_query = 0.0_wp, r_in_parked = 0.0_wp
   end type particle_kind_type

   !> What building a kind needs of the run's configuration (filled by the driver).
   type :: kind_params_type
      !> Namelist file (for messages).
      character(len=:), allocatable :: file
      !> Shell layers (0: none), their thicknesses and whether those are in mm (else fractions
      !> of the particle length).
      integer :: nlayer = 0
      real(wp), allocatable :: thickness(:)
      integer :: unit = thickness_unit%fraction_of_length
      !> Shell mode (`shell_mode`).
      integer :: mode = shell_mode%exclude
      !> Extended-grid size of the contact bodies.
      integer :: n_ext = 40
      !> Width range of each sieve (mm).
      real(wp), allocatable :: min_width(:), max_width(:)
   end type kind_params_type

   !> Bookkeeping of the kinds of a run.
   type :: kind_set_type
      !> Parameters.
      type(kind_params_type) :: p
      !> Width levels per sieve (1, or width_levels with shells in mm).
      integer :: nlev = 1
      !> First kind and number of kinds of each sieve.
      integer, allocatable :: first(:), count(:)
      !> The kind each kind is a copy of (itself when it is built on its own).
      integer, allocatable :: same(:)
      !> The kind of the same (shape, order) whose geometry and bare body a kind copied (set when built).
      integer, allocatable :: base(:)
      !> Kinds built so far; kinds whose geometry and bare body are built (`base`s).
      logical, allocatable :: built(:), base_built(:)
      !> The run's shapes and names (the model's).
      type(sh_expansion_type), allocatable :: shapes(:)
      type(string_type), allocatable :: names(:)
   contains
      !> Build the kinds of a list that are not built yet.
      procedure :: build
   end type kind_set_type

contains

   !> Describe every kind of a run (nothing is built yet): sieve s uses the shapes
   !> first_shape(s) + 1 .. first_shape(s) + nshape(s) at order min(order(s), nmax) (order < 0:
   !> the shape's own order).
   subroutine new_kind_set(ks, kinds, params, shapes, names, first_shape, nshape, order)
      !> Bookkeeping.
      type(kind_set_type), intent(out) :: ks
      !> Kinds (described, not built).
      type(particle_kind_type), allocatable, intent(out) :: kinds(:)
      !> Parameters.
      type(kind_params_type), intent(in) :: params
      !> The run's shapes and their names.
      type(sh_expansion_type), intent(in) :: shapes(:)
      character(len=*), intent(in) :: names(:)
      !> Per sieve: shapes before its first one, number of its shapes, order (< 0: full).
      integer, intent(in) :: first_shape(:), nshape(:), order(:)
      integer :: nsieve, s, n, lev, k, i, j
      ks%p = params
      ks%shapes = shapes
      allocate (ks%names(size(names)))
      do i = 1, size(names)
         ks%names(i)%s = trim(names(i))
      end do
      nsieve = size(first_shape)
      ks%nlev = 1
      if (params%nlayer > 0 .and. params%unit == thickness_unit%mm) ks%nlev = width_levels
      allocate (ks%first(nsieve), ks%count(nsieve))
      n = 0
      do s = 1, nsieve
         ks%first(s) = n + 1
         ks%count(s) = nshape(s) * ks%nlev
         n = n + ks%count(s)
      end do
      allocate (kinds(n))
      do s = 1, nsieve
         do lev = 1, ks%nlev
            do k = 1, nshape(s)
               i = ks%first(s) + (lev - 1) * nshape(s) + k - 1
               kinds(i)%shape = first_shape(s) + k
               kinds(i)%sieve = s
               kinds(i)%level = merge(lev, 0, ks%nlev > 1)
               kinds(i)%order = shapes(kinds(i)%shape)%nmax
               if (order(s) >= 0) kinds(i)%order = min(order(s), kinds(i)%order)
            end do
         end do
      end do
      ! a kind equal to an earlier one (same shape and order, and with shells in mm the same width:
      ! e.g. two sieves of one source) is built once and copied (build)
      allocate (ks%same(n), ks%built(n), ks%base(n), ks%base_built(n))
      ks%built = .false.
      ks%base_built = .false.
      ks%base = [(i, i=1, n)]
      do i = 1, n
         ks%same(i) = i
         do j = 1, i - 1
            if (ks%same(j) /= j) cycle
            if (kinds(j)%shape /= kinds(i)%shape .or. kinds(j)%order /= kinds(i)%order) cycle
            if (ks%nlev > 1) then
               if (level_width(params, kinds(j)) /= level_width(params, kinds(i))) cycle
            end if
            ks%same(i) = j
            exit
         end do
      end do
   end subroutine new_kind_set

   !> Build the kinds `list` that are not built yet: the geometry and bare bodies of their bases
   !> (`base`) in parallel, then their originals' (`same`) shells in parallel, then the copies. A
   !> failure (a shell that cannot be built) is returned.
   subroutine build(self, kinds, list, error)
      !> Bookkeeping.
      class(kind_set_type), intent(inout) :: self
      !> Kinds.
      type(particle_kind_type), intent(inout) :: kinds(:)
      !> Kinds wanted.
      integer, intent(in) :: list(:)
      !> Error of the first kind that failed.
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: errs(:)
      logical, allocatable :: want(:), failed(:)
      integer, allocatable :: todo(:)
      integer :: i, j, k, sieve, level
      allocate (want(size(kinds)))
      want = .false.
      do i = 1, size(list)
         if (.not. self%built(list(i))) want(self%same(list(i))) = .true.
      end do
      want = want .and. .not. self%built
      todo = pack([(k, k=1, size(kinds))], want)
      if (size(todo) > 0) then
         ! the bases first: geometry and bare body, once per (shape, order): a kind of the same
         ! (shape, order) built earlier, else the first such kind of this list
         do i = 1, size(todo)
            k = todo(i)
            if (self%base_built(k)) then
               self%base(k) = k
               cycle
            end if
            self%base(k) = k
            do j = 1, size(kinds)
               if (kinds(j)%shape /= kinds(k)%shape .or. kinds(j)%order /= kinds(k)%order) cycle
               if (self%base_built(j) .or. (j < k .and. want(j))) then
                  if (self%base_built(j) .or. self%base(j) == j) then
                     self%base(k) = j
                     exit
                  end if
               end if
            end do
         end do
         block
            integer, allocatable :: bases(:)
            bases = pack(todo, self%base(todo) == todo .and. .not. self%base_built(todo))
            if (size(bases) > 0) then
               allocate (errs(size(bases)), failed(size(bases)))
               failed = .false.
               call build_originals(self, kinds, bases, failed, errs, .true.)
               do i = 1, size(bases)
                  if (failed(i)) then
                     call fatal_error(error, errs(i)%message, errs(i)%stat)
                     return
                  end if
               end do
               self%base_built(bases) = .true.
               deallocate (errs, failed)
            end if
         end block
         do i = 1, size(todo)
            k = todo(i)
            if (self%base(k) /= k) then
               call copy_base(kinds(self%base(k)), kinds(k))
               self%base_built(k) = .true.
            end if
         end do
         allocate (errs(size(todo)), failed(size(todo)))
         failed = .false.
         call build_originals(self, kinds, todo, failed, errs, .false.)
         do i = 1, size(todo)
            if (failed(i)) then
               call fatal_error(error, errs(i)%message, errs(i)%stat)
               return
            end if
         end do
         self%built(todo) = .true.
      end if
      do i = 1, size(list)
         k = list(i)
         if (self%built(k)) cycle
         sieve = kinds(k)%sieve
         level = kinds(k)%level
         kinds(k) = kinds(self%same(k))
         kinds(k)%sieve = sieve
         kinds(k)%level = level
         self%built(k) = .true.
      end do
   end subroutine build

   !> A kind's geometry and bare body from its base (another width level of its shape and order).
   subroutine copy_base(from, kd)
      type(particle_kind_type), intent(in) :: from
      type(particle_kind_type), intent(inout) :: kd
      kd%width = from%width
      kd%length = from%length
      kd%volume = from%volume
      kd%body = from%body
      kd%r_out = from%body%r_max
      kd%r_in_query = from%body%r_min
      kd%r_in_parked = from%body%r_min
   end subroutine copy_base

   !> Build kinds(todo) in parallel (each kind by one thread; failures in failed/errs): their
   !> geometry and bare body (`bases`) or, with these in place, their shells.
   subroutine build_originals(ks, kinds, todo, failed, errs, bases)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(inout) :: kinds(:)
      integer, intent(in) :: todo(:)
      logical, intent(inout) :: failed(:)
      type(error_type), intent(inout) :: errs(:)
      logical, intent(in) :: bases
      integer :: i
      !$omp parallel do default(none) shared(ks, kinds, todo, failed, errs, bases) private(i) schedule(dynamic)
      do i = 1, size(todo)
         block
            type(error_type), allocatable :: err
            associate (kd => kinds(todo(i)))
               if (bases) then
                  call prepare_base(ks%p, ks%shapes(kd%shape), kd, err)
               else
                  call prepare_shells(ks%p, ks%shapes(kd%shape), ks%names(kd%shape)%s, kd, err)
               end if
            end associate
            if (allocated(err)) then
               failed(i) = .true.
               errs(i) = err
            end if
         end block
      end do
      !$omp end parallel do
   end subroutine build_originals

   !> Width of a kind's width level (shells in mm).
   pure real(wp) function level_width(p, kd) result(w)
      type(kind_params_type), intent(in) :: p
      type(particle_kind_type), intent(in) :: kd
      w = p%min_width(kd%sieve) + (kd%level - 0.5_wp) * (p%max_width(kd%sieve) - p%min_width(kd%sieve)) &
          / width_levels
   end function level_width

   !> Geometry and bare contact body of one kind (shared by its width levels).
   subroutine prepare_base(p, shape, kd, error)
      type(kind_params_type), intent(in) :: p
      type(sh_expansion_type), intent(in) :: shape
      type(particle_kind_type), intent(inout) :: kd
      type(error_type), allocatable, intent(out) :: error
      type(shape_geometry_type) :: g
      type(sh_expansion_type) :: s
      s = sh_truncate(shape, kd%order)
      call compute_geometry(s, g)
      kd%width = g%width
      kd%length = g%length
      kd%volume = g%volume
      call new_contact_body(kd%body, s, error, next=p%n_ext)
      if (allocated(error)) return
      kd%r_out = kd%body%r_max
      kd%r_in_query = kd%body%r_min
      kd%r_in_parked = kd%body%r_min
   end subroutine prepare_base

   !> Shells of one kind whose geometry and bare body are in place.
   subroutine prepare_shells(p, shape, name, kd, error)
      type(kind_params_type), intent(in) :: p
      type(sh_expansion_type), intent(in) :: shape
      character(len=*), intent(in) :: name
      type(particle_kind_type), intent(inout) :: kd
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s
      type(shell_report_type), allocatable :: reports(:)
      real(wp), allocatable :: t(:)
      real(wp) :: w, sc
      integer :: k
      if (p%nlayer == 0) return
      s = sh_truncate(shape, kd%order)
      sc = 1.0_wp
      if (p%unit == thickness_unit%mm) then
         w = level_width(p, kd)
         sc = w / kd%width
      end if
      t = thickness_to_shape_units(p%thickness, p%unit, kd%length, sc)
      call build_layers(s, t, kd%layers, reports, error, label=name)
      if (allocated(error)) then
         error%message = p%file//": &shells: "//error%message
         return
      end if
      allocate (kd%layer_volume(size(t)))
      do k = 1, size(t)
         kd%layer_volume(k) = reports(k)%outer_volume
      end do
      ! overlapping shells do not take part in the parking: no contact body for them
      if (p%mode == shell_mode%overlap) return
      allocate (kd%shell_body)
      call new_contact_body(kd%shell_body, kd%layers(size(t)), error, next=p%n_ext)
      if (allocated(error)) return
      kd%r_out = max(kd%r_out, kd%shell_body%r_max)
      kd%r_in_query = kd%shell_body%r_min
      if (p%mode == shell_mode%exclude) kd%r_in_parked = kd%shell_body%r_min
   end subroutine prepare_shells
end module anm_parking_kinds
